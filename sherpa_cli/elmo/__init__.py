"""Elmo SimplIQ layer: command table, binary-interpreter codec and fault decoding.

Pure code only (no bus, no printing); import the submodules directly, e.g.
``from sherpa_cli.elmo import codec``.
"""
