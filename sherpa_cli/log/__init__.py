"""`sherpa log`: recording joint states (record.py: TPDOs on SYNC within the bus budget; recording.py:
the CSV), capturing and decoding raw frames (capture.py, candecode.py), step metrics (step_metrics.py,
pure) and plots (plot.py, matplotlib imported lazily); MCAP recordings and captures (mcap_out.py, ROS 2
messages in ros_msgs.py) and the Foxglove live view (foxglove_live.py, layout foxglove_layout.py), their
libraries imported lazily too.

May import devices, bus, elmo, joints, config, output_files, errors; never motion, ops, cli or sim
(`log step` moves a joint, so it is a procedure: ops/step.py).
"""
