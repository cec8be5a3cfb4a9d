"""sherpa-cli: commissioning and diagnostics for the SHERPA arm's Elmo SimplIQ drives."""

__version__ = "0.1.0"
