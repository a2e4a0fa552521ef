"""Tilt from a static accelerometer (:mod:`.angles`: single-axis arcsin, dual- and
three-axis atan2, with averaging) and the tilt error budget (:mod:`.budget`: worst case
and RSS, noise multiplier from the mission profile); ``imubench tilt``
(docs/calibration.md). The submodules are imported where used (the budget needs
scipy.stats, which the command line should not load for ``--help``)."""
