"""Errors of the MQTT layer, inside the imubench exception family."""

from __future__ import annotations

from imubench.errors import ImubenchError


class MqttError(ImubenchError):
    """An MQTT broker or publisher could not do what was asked (bad name, port taken, ...)."""


class MalformedPacket(MqttError):  # noqa: N818 (the MQTT specification's own term)
    """A client sent bytes that are not a valid MQTT 3.1.1 control packet.

    The broker closes that client's connection (MQTT 3.1.1 section 4.8) and logs the reason.
    """
