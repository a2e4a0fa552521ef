"""Hardware-in-the-loop test jig: every board tested, calibrated and judged with honest
statistics (docs/jig.md).

* :mod:`.station`, :mod:`.limits`: the station and limits files;
* :mod:`.dut`, :mod:`.fixtures`: the board under test and what moves it;
* :mod:`.procedures`, :mod:`.analysis`, :mod:`.calibrate`: captures, measurements with
  confidence intervals, the calibration;
* :mod:`.plugin`, :mod:`.suite`: the pytest plugin and the shipped acceptance suite;
* :mod:`.runner`, :mod:`.report`, :mod:`.store`, :mod:`.publish`: ``imubench jig run``.
"""
