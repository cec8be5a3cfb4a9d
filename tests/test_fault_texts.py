"""Every EMCY, MF, SR and EC code of elmo-protocol.md has a one-line meaning, most a "what to check".

The code lists are parsed from the protocol doc when it is reachable (so a code added to the
doc without a text fails here), and checked against a copy embedded below either way.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import pytest

from sherpa_cli.elmo.faults import (
    EC_CODES,
    EMCY_CODES,
    EMCY_PVT,
    MF_BITS,
    PVT_CODES,
    decode_emcy,
    decode_mf,
    describe_ec,
    describe_sr,
    sr_problems,
)

DOC = Path(__file__).resolve().parents[2] / "shared" / "docs" / "elmo-protocol.md"
if not DOC.exists():
    DOC = Path("/work/shared/docs/elmo-protocol.md")

# The doc's tables as of this writing (sections 2.5 and 3.6).
EMBEDDED_EC = {2, 3, 7, 9, 10, 11, 13, 16, 19, 21, 23, 26, 28, 33, 34, 47, 48, 51, 54, 57, 58, 60, 61, 67, 68,
               71, 72, 82, 83, 122, 166, 168, 172, 178, 179, 12, 14, 15, 22, 25, 43, 90, 92}
EMBEDDED_MF = {0x1, 0x4, 0x8, 0x10, 0x40, 0x80, 0x100, 0x200, 0x400, 0x800, 0x1000, 0x10000, 0x20000, 0x40000,
               0x80000, 0x200000, 0x400000, 0x20000000}
EMBEDDED_EMCY = {0x2340, 0x3120, 0x3130, 0x3310, 0x4310, 0x5280, 0x5281, 0x5400, 0x5441, 0x5442, 0x6180, 0x6181,
                 0x6200, 0x6300, 0x6320, 0x7121, 0x7300, 0x7380, 0x7381, 0x7382, 0x8110, 0x8130, 0x8140, 0x8200,
                 0x8210, 0x8311, 0x8380, 0x8381, 0x8480, 0x8481, 0x8611, 0x8680, 0xFF01, 0xFF02, 0xFF10, 0xFF20,
                 0xFF40}
EMBEDDED_PVT = {0x56, 0x5B, 0x5C, 0x34, 0x07, 0x08, 0x09, 0xA6}
EMBEDDED_SR_BITS = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 24, 25, 26, 27, 28, 29}
OBJECT_INDEXES = {0x1001, 0x2F21}  # objects named in section 3.6, not EMCY codes


def _section(text: str, start: str, end: str) -> str:
    return text[text.index(start):text.index(end, text.index(start))]


@pytest.fixture(scope="module")
def doc() -> str:
    if not DOC.exists():
        pytest.skip(f"{DOC} not reachable; the embedded lists are checked by the other tests")
    return DOC.read_text(encoding="utf-8")


def doc_ec(text: str) -> set[int]:
    table = _section(text, "**EC — error code", "Full lists:")
    codes = set()
    for line in table.splitlines():
        if line.startswith("| ") and not line.startswith("| EC") and not line.startswith("|---"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            for cell in (cells[0], cells[2]):
                codes.update(int(n) for n in re.findall(r"\d+", cell))
    bliss = table[table.index("Only in [BLISS]"):]
    codes.update(int(n) for n in re.findall(r"[:,] (\d+) [a-zA-Z]", bliss))
    return codes


def doc_mf(text: str) -> set[int]:
    table = _section(text, "**MF — motor failure", "**EC — error code")
    return {int(m, 16) for m in re.findall(r"^\| 0x([0-9A-F]{8}) \|", table, re.M)}


def doc_emcy(text: str) -> tuple[set[int], set[int]]:
    sec = _section(text, "### 3.6", "### 3.7")
    codes = {int(c, 16) for c in re.findall(r"\b0x([0-9A-F]{4})\b", sec)} - OBJECT_INDEXES - {EMCY_PVT}
    pvt_text = sec[sec.index("PVT/PT emergencies"):]
    pvt_text = pvt_text[pvt_text.index("byte 3:"):]  # after "register 0x81"
    pvt = {int(c, 16) for c in re.findall(r"\b0x([0-9A-F]{2}) [a-zA-Z]", pvt_text)}
    return codes, pvt


def doc_sr_bits(text: str) -> set[int]:
    table = _section(text, "**SR — status register", "Object 0x1002")
    bits: set[int] = set()
    for lo, hi, meaning in re.findall(r"^\| (\d+)(?:\.\.(\d+))? \| (.*) \|$", table, re.M):
        if "not used" in meaning or "unused" in meaning:
            continue
        bits.update(range(int(lo), int(hi or lo) + 1))
    return bits


# -- the doc and the embedded copy agree (a doc change shows here first) ---------------------------

def test_doc_lists_match_the_embedded_copy(doc):
    assert doc_ec(doc) == EMBEDDED_EC
    assert doc_mf(doc) == EMBEDDED_MF
    assert doc_emcy(doc) == (EMBEDDED_EMCY, EMBEDDED_PVT)
    assert doc_sr_bits(doc) == EMBEDDED_SR_BITS


def test_every_code_in_the_doc_has_a_text(doc):
    ec, mf, (emcy, pvt) = doc_ec(doc), doc_mf(doc), doc_emcy(doc)
    assert ec <= set(EC_CODES), f"EC codes without text: {sorted(ec - set(EC_CODES))}"
    assert mf - {0x1000} <= set(MF_BITS), f"MF bits without text: {sorted(mf - set(MF_BITS))}"
    assert emcy <= set(EMCY_CODES), f"EMCY codes without text: {sorted(map(hex, emcy - set(EMCY_CODES)))}"
    assert pvt <= set(PVT_CODES), f"PVT sub-codes without text: {sorted(map(hex, pvt - set(PVT_CODES)))}"


# -- texts: one line, known, and checks where the meaning points at something to look at ----------

def _one_line(text: str) -> bool:
    return bool(text.strip()) and "\n" not in text and not text.startswith("unknown")


@pytest.mark.parametrize("code", sorted(EMBEDDED_EC))
def test_ec_has_a_one_line_text_and_a_check(code):
    entry = EC_CODES[code]
    assert _one_line(entry.text)
    assert entry.check, f"EC {code} ({entry.text}) has no 'what to check'"
    assert describe_ec(code) == f"{entry.text} - check {entry.check}"


@pytest.mark.parametrize("mask", sorted(EMBEDDED_MF - {0x1000}))
def test_mf_bit_has_a_one_line_text_and_a_check(mask):
    fault = MF_BITS[mask]
    assert _one_line(fault.text) and fault.check, hex(mask)
    assert decode_mf(mask).faults == (fault,)


@pytest.mark.parametrize(("value", "text", "check"), [
    (0x3000, "under-voltage", "the DC supply voltage"),
    (0x5000, "over-voltage", "regeneration"),
    (0xB000, "short circuit", "short"),
    (0xD000, "over-temperature", "cooling"),
])
def test_mf_servo_faults(value, text, check):
    (fault,) = decode_mf(value).faults
    assert text in fault.text and check in fault.check and fault.known


@pytest.mark.parametrize("code", sorted(EMBEDDED_EMCY))
def test_emcy_has_a_one_line_text_and_a_check(code):
    entry = EMCY_CODES[code]
    assert _one_line(entry.text) and entry.check, hex(code)
    emcy = decode_emcy(struct.pack("<HBBHH", code, 0x81, 0, 0, 0))
    assert emcy.known and emcy.text.startswith(f"EMCY 0x{code:04X}: {entry.text}")
    assert emcy.text.endswith(f" - check {entry.check}")


@pytest.mark.parametrize("sub", sorted(EMBEDDED_PVT))
def test_pvt_sub_code_has_a_text(sub):
    entry = PVT_CODES[sub]
    assert _one_line(entry.text)
    assert decode_emcy(struct.pack("<HBBHH", EMCY_PVT, 0x81, sub, 0, 0)).meaning == entry.text


def test_position_limit_emcy_names_the_limits_and_switches():
    text = decode_emcy(struct.pack("<HBBHH", 0x8680, 0x01, 0, 0, 0)).text
    assert text == "EMCY 0x8680: position limit exceeded - check LL[3]/HL[3] and the joint's switches"


def test_emcy_with_an_elmo_code_shows_its_text():
    text = decode_emcy(struct.pack("<HBBHH", 0x6300, 0x01, 57, 0x2012, 0)).text
    assert "(error 57: motor must be off)" in text


@pytest.mark.parametrize("bit", sorted(EMBEDDED_SR_BITS))
def test_every_documented_sr_bit_changes_the_decoding(bit):
    assert describe_sr(1 << bit) != describe_sr(0), f"SR bit {bit} is not decoded"


def test_sr_problems_carry_checks():
    value = (1 << 6) | (1 << 27) | (1 << 28) | (1 << 29) | 0b0011
    problems = sr_problems(value)
    assert [p.text for p in problems] == [
        "drive problem: under-voltage", "motor failure latched", "CPU fault: stack overflow or CPU exception",
        "error in user program", "stopped by a limit switch, stop switch or VL[3]/VH[3]"]
    assert all(p.check for p in problems)
    assert sr_problems(1 << 4 | 5 << 7) == []  # motor on in UM 5: nothing to worry about
