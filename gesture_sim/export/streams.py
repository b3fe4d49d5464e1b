"""``live --stream ADDRESS``: the pose sender for an address (VMC over OSC or JSON over UDP).

It sits beside both senders (:mod:`gesture_sim.export.vmc`, :mod:`gesture_sim.export.json_stream`)
so that neither imports the other.
"""

from __future__ import annotations

from gesture_sim.errors import GestureSimError
from gesture_sim.export.json_stream import JsonSender
from gesture_sim.export.vmc import UdpPoseSender, VmcSender

__all__ = ["SCHEMES", "open_stream"]


#: ``live --stream`` address schemes -> protocol (a bare ``HOST:PORT`` is VMC).
SCHEMES = ("vmc", "json")


def open_stream(address: str) -> UdpPoseSender:
    """The pose sender of ``gesture-sim live --stream ADDRESS``: ``HOST:PORT`` or
    ``vmc://HOST:PORT`` -> :class:`VmcSender`, ``json://HOST:PORT`` ->
    :class:`gesture_sim.export.json_stream.JsonSender`. A bad address or an unknown scheme:
    :class:`~gesture_sim.errors.GestureSimError` (one line)."""
    text = str(address).strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        return VmcSender(text)
    if scheme.lower() == "vmc":
        return VmcSender(rest)
    if scheme.lower() == "json":
        return JsonSender(rest)
    raise GestureSimError(f"stream address {address!r}: unknown protocol {scheme!r}; use "
                          f"HOST:PORT or vmc://HOST:PORT (VMC over OSC) or json://HOST:PORT "
                          "(JSON over UDP)")
