"""The command line: the typer app (app.py), one module per command group (parse -> call ops -> render),
the error boundary (boundary.py: `run`, exit codes), the one output sink (output.py) and the
process-wide state of one invocation (context.py, which also wires the in-process simulator for --sim).

May import every package below it (recipes, ops, motion, log, devices, bus, elmo, joints, config) and
the simulator. Nothing imports the CLI; recipe steps run command lines through boundary.run.
A new command: a module here plus a procedure in ops/ (docs/architecture.md).
"""
