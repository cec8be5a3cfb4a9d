"""python-can's ``virtual`` interface without its per-frame overhead (the in-process ``--sim`` bus).

python-can's VirtualBus deep-copies every frame once per receiver (about 7 us with copy's
machinery) and hands it over through a ``queue.Queue``, whose put and get each run a Python
Condition. A round trip to the in-process simulator crosses the bus twice, so that overhead
alone held the ``roundtrip`` benchmark to half its goal.

:class:`LeanVirtualBus` *is* a VirtualBus: it joins the same process-wide channels, so it talks
to plain VirtualBus instances, and it keeps their delivery rules -- every receiver gets its own
copy, stamped with the send time (or the sender's, with ``preserve_timestamps``), the channel
and ``is_rx``, in send order; a bounded ``rx_queue_size`` still blocks and then fails the send.
Only the copy (a direct constructor call) and, for unbounded receive queues, the queue (the
C-implemented ``queue.SimpleQueue``, same put/get signature) differ.
"""

from __future__ import annotations

import queue
import time
from typing import Any

from can import CanOperationError, Message
from can.interfaces.virtual import VirtualBus, channels_lock


class LeanVirtualBus(VirtualBus):
    def __init__(self, channel: Any = "channel-0", receive_own_messages: bool = False, rx_queue_size: int = 0,
                 preserve_timestamps: bool = False, **kwargs: Any) -> None:
        super().__init__(channel=channel, receive_own_messages=receive_own_messages, rx_queue_size=rx_queue_size,
                         preserve_timestamps=preserve_timestamps, **kwargs)
        if rx_queue_size <= 0:
            with channels_lock:
                old, lean = self.queue, queue.SimpleQueue()
                self.channel[self.channel.index(old)] = lean
                self.queue = lean  # type: ignore[assignment]
                # a frame a sender put into the old queue while we swapped is kept, in order
                while True:
                    try:
                        lean.put(old.get_nowait())
                    except queue.Empty:
                        break

    def send(self, msg: Message, timeout: float | None = None) -> None:
        self._check_if_open()
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        data = bytes(msg.data)
        own = self.queue
        all_sent = True
        for bus_queue in self.channel:
            if bus_queue is own and not self.receive_own_messages:
                continue
            copy = Message(timestamp=timestamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                           is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame,
                           channel=self.channel_id, dlc=msg.dlc, data=data, is_fd=msg.is_fd,
                           is_rx=bus_queue is not own, bitrate_switch=msg.bitrate_switch,
                           error_state_indicator=msg.error_state_indicator)
            try:
                bus_queue.put(copy, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise CanOperationError("Could not send message to one or more recipients")


def open_can_bus(**kwargs: Any) -> Any:
    """``can.Bus(**kwargs)``, except that an explicit ``interface="virtual"`` gets a LeanVirtualBus.

    The configuration is resolved as ``can.Bus`` does it (python-can's own config files and
    environment fill what ``kwargs`` leave open), so only the class differs.
    """
    import can

    if kwargs.get("interface") != "virtual" or "ignore_config" in kwargs or "config_context" in kwargs:
        return can.Bus(**kwargs)
    config = can.util.load_config(config=dict(kwargs))
    del config["interface"]
    channel = config.pop("channel", None)
    return LeanVirtualBus(**config) if channel is None else LeanVirtualBus(channel, **config)
