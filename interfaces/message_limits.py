"""How large a whole Zenoh message a session of the cell takes: Zenoh's own limit, set from the message size bounds.

A receiver checks a payload against its type's bound
(:data:`~interfaces.messages.MAX_PAYLOAD_BYTES`, :meth:`~interfaces.codec.Decoder.check_size`) only once
Zenoh has handed it over, and Zenoh hands over a message only once it has put its fragments back together:
without a limit of Zenoh's own (1 GiB by default), a 128 MB put cost the controller 128 MB before any check
of ours saw it. Zenoh's ``transport/link/rx/max_message_size`` [bytes] (:data:`MAX_MESSAGE_SIZE_PATH`,
"maximum size of the defragmentation buffer at receiver end; fragmented messages that are larger than the
configured size will be dropped") is that limit: past it Zenoh drops the message while reassembling it, and
the link goes on.

Measured over TCP on loopback (zenoh-python 1.10), a receiving session's resident memory when two 128 MiB
puts (congestion control ``BLOCK``) reach a subscriber that only takes their length: Zenoh's default
27 -> 233 MB, both delivered; :func:`max_message_bytes` (16.1 MB) 27 -> 57 MB at the peak and 33 MB after,
both dropped; a 64 MiB limit 27 -> 133 MB at the peak. The reassembly buffer grows to about twice the limit
before it is dropped, so the limit bounds what one message costs a receiver to a few times itself.

:func:`max_message_bytes` is the cell's largest bound, a :class:`~interfaces.messages.CameraFrame`'s, plus
:data:`MESSAGE_OVERHEAD_BYTES` for Zenoh's own header (the key, the encoding: tens of bytes). A session that
takes ROS camera images through zenoh-bridge-ros2dds (perception with a ``ros:`` source) needs the bound of
those instead, :data:`ROS_IMAGE_MAX_BYTES` (perception drops a larger one, counted).
"""

from __future__ import annotations

from collections.abc import Iterable

from .messages import MAX_PAYLOAD_BYTES, MESSAGE_TYPES, Message

#: Zenoh's configuration path of the receivers' limit on a whole (reassembled) message [bytes].
MAX_MESSAGE_SIZE_PATH = "transport/link/rx/max_message_size"
#: What a Zenoh message adds to its payload [bytes], with room to spare (measured: under 100 with a 60-character
#: key; the limit counts the whole reassembled message).
MESSAGE_OVERHEAD_BYTES = 64 * 1024
#: The largest ROS image perception takes through the bridge [bytes] (``perception.ros_images.MAX_IMAGE_BYTES``:
#: 8K RGBA is 133 MB, a 4K RGB frame 25 MB).
ROS_IMAGE_MAX_BYTES = 64 * 1024 * 1024


def max_message_bytes(types: Iterable[type[Message]] = MESSAGE_TYPES, ros_images: bool = False) -> int:
    """The receivers' limit on a whole Zenoh message [bytes] for a session that takes messages of ``types`` (by
    default every type of the cell) and, with ``ros_images``, ROS camera images: the largest payload bound among
    them plus :data:`MESSAGE_OVERHEAD_BYTES`. Set it at :data:`MAX_MESSAGE_SIZE_PATH`.

    Raises ValueError for a type with no size bound (every message type of the cell has one).
    """
    bounds = []
    for t in types:
        if t not in MAX_PAYLOAD_BYTES:
            raise ValueError(f"{t.__name__} has no size bound in interfaces.messages.MAX_PAYLOAD_BYTES")
        bounds.append(MAX_PAYLOAD_BYTES[t])
    if ros_images:
        bounds.append(ROS_IMAGE_MAX_BYTES)
    if not bounds:
        raise ValueError("max_message_bytes needs at least one message type or ros_images")
    return max(bounds) + MESSAGE_OVERHEAD_BYTES
