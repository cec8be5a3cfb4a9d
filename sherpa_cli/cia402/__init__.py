"""The CiA 402 drive type: the power state machine and objects (protocol.py, pure) and the drive over
SDO (drive.py), which implements sherpa_cli.drive.Drive (docs/cia402.md)."""
