"""Elmo SimplIQ: the protocol's numbers (protocol.py: COB-ID bases, NMT codes, objects, unit modes,
defined once), the command table (commands.py), the binary-interpreter codec (codec.py), fault
decoding (faults.py) -- pure code, no I/O -- and the drive client (client.py) over a Transport
(transport.py: a canopen.Network adapter, and a fake for byte-exact transcripts).

May import errors only (and canopen/python-can lazily in transport.py). Import submodules directly,
e.g. ``from sherpa_cli.elmo import codec``.
"""
