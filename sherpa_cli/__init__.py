"""sherpa-cli: commissioning and diagnostics for the SHERPA arm's Elmo SimplIQ drives.

From Python: ``from sherpa_cli import Arm`` (docs/api.md). The API is imported on first use, so
the command line does not pay for it at startup.
"""

from sherpa_cli.version import __version__

# not typing's: the console script imports this package before its signal handlers are in place
# (cli/entry.py), and typing is not loaded at start-up; mypy treats any TYPE_CHECKING alike
TYPE_CHECKING = False

__all__ = ["Arm", "__version__"]

if TYPE_CHECKING:
    from sherpa_cli.api import Arm as Arm


def __getattr__(name: str) -> object:
    if name == "Arm":
        from sherpa_cli.api import Arm

        return Arm
    raise AttributeError(f"module 'sherpa_cli' has no attribute {name!r}")
