"""What a lab's daemons publish, seen from the broker: every sensor's status, Allan curves,
noise readouts and jig results (``imubench view`` and ``imubench fleet status``).

- :mod:`~imubench.fleet.inventory`: the state of every ``imubench/<station>/<sensor>``
  built from its ``status``, ``allan`` and ``jig`` messages;
- :mod:`~imubench.fleet.readouts`: N, B, K read off a live Allan deviation curve;
- :mod:`~imubench.fleet.listener`: an MQTT subscriber that feeds an inventory.
"""

from __future__ import annotations

from imubench.errors import ImubenchError


class FleetError(ImubenchError):
    """The fleet view or the fleet inventory cannot do what was asked."""


__all__ = ["FleetError"]
