"""A recipe run's report for machines: JSON, and JUnit XML that CI servers show as tests."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from sherpa_cli.recipes.runner import DECLINED, FAILED, INTERRUPTED, SKIPPED, RecipeReport


def report_json(report: RecipeReport) -> str:
    return json.dumps(report.as_json(), indent=2, ensure_ascii=False) + "\n"


def report_junit(report: RecipeReport) -> str:
    """One <testcase> per step; a failed, declined or interrupted step is a <failure>."""
    failures = sum(1 for r in report.results if r.status in (FAILED, DECLINED, INTERRUPTED))
    total_time = sum(r.duration_s for r in report.results)
    suites = ET.Element("testsuites")
    suite = ET.SubElement(suites, "testsuite", name=report.recipe.name, tests=str(len(report.results)),
                          failures=str(failures), errors="0", skipped=str(report.count(SKIPPED)),
                          time=f"{total_time:.3f}")
    for r in report.results:
        case = ET.SubElement(suite, "testcase", classname=f"recipe.{report.recipe.name}",
                             name=f"{r.step.number:02d}-{r.step.name}", time=f"{r.duration_s:.3f}")
        if r.status == SKIPPED:
            ET.SubElement(case, "skipped", message="; ".join(r.failures) or "skipped")
        elif r.status in (FAILED, DECLINED, INTERRUPTED):
            message = "; ".join(r.failures) or r.status
            ET.SubElement(case, "failure", message=message, type=r.status).text = message
        if r.step.kind == "run":
            what = f"$ {r.step.command_text() if not r.argv else 'sherpa ' + ' '.join(r.argv)}\n"
            ET.SubElement(case, "system-out").text = what + r.stdout
            if r.stderr:
                ET.SubElement(case, "system-err").text = r.stderr
        else:
            ET.SubElement(case, "system-out").text = f"? {r.step.confirm}\n{r.answer}\n"
    ET.indent(suites)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def check_report_paths(json_path: Path | None, junit_path: Path | None) -> None:
    """Refuse report paths that cannot take a report before any step runs (UsageError)."""
    from sherpa_cli.errors import UsageError
    from sherpa_cli.output_files import check_output_path, is_stdout

    if is_stdout(json_path) and is_stdout(junit_path):
        raise UsageError("--report - and --junit -: only one report can go to stdout",
                         hint="write the other one to a file")
    for option, path in (("--report", json_path), ("--junit", junit_path)):
        check_output_path(path, option, "the report")


def write_reports(report: RecipeReport, json_path: Path | None, junit_path: Path | None) -> None:
    """Write the reports; an unwritable path is a UsageError naming the option and the file."""
    from sherpa_cli.errors import UsageError
    from sherpa_cli.output_files import write_output

    for option, path, render in (("--report", json_path, report_json), ("--junit", junit_path, report_junit)):
        if path is None:
            continue
        try:
            write_output(path, render(report), option, what="the report")
        except UsageError as exc:
            raise UsageError(exc.message, hint=f"the recipe itself ended: {report.outcome}") from None
