"""sherpa-cli: commissioning and diagnostics for the SHERPA arm's Elmo SimplIQ drives.

From Python: ``from sherpa_cli import Arm`` (docs/api.md). The API is imported on first use, so
the command line does not pay for it at startup.
"""

from typing import TYPE_CHECKING

from sherpa_cli.version import __version__

__all__ = ["Arm", "__version__"]

if TYPE_CHECKING:
    from sherpa_cli.api import Arm as Arm


def __getattr__(name: str) -> object:
    if name == "Arm":
        from sherpa_cli.api import Arm

        return Arm
    raise AttributeError(f"module 'sherpa_cli' has no attribute {name!r}")
