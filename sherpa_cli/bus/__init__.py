"""Buses from the config: python-can buses, one paced canopen Network per bus, per-bus concurrency.

Imports python-can / canopen lazily (inside functions) so the CLI can import this package
without paying for the CAN stack.
"""
