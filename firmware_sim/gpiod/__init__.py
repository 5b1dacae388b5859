"""A simulated GPIO character device with a python-gpiod 2.x compatible API.

Two sides live here, one concept per module:

*Device-code side* -- the subset of python ``gpiod`` 2.x that the edge code
uses, with the same names, signatures, return types and exceptions, laid out
like the real package:

* :mod:`~firmware_sim.gpiod.line` -- ``gpiod.line``: the ``Value``,
  ``Direction``, ``Bias``, ``Drive``, ``Edge`` and ``Clock`` enums;
* :mod:`~firmware_sim.gpiod.line_settings` -- ``LineSettings``;
* :mod:`~firmware_sim.gpiod.edge_event` -- ``EdgeEvent``;
* :mod:`~firmware_sim.gpiod.exception` -- ``ChipClosedError``,
  ``RequestReleasedError``;
* :mod:`~firmware_sim.gpiod.chip` -- ``Chip`` and ``ChipInfo``;
* :mod:`~firmware_sim.gpiod.line_request` -- ``LineRequest`` (values, edge
  events in virtual time).

*Simulator side* -- the hardware and the kernel behind it:

* :mod:`~firmware_sim.gpiod.sim_line` -- the state of one line: physical
  level, bias, the request holding it, and what a released line does (it
  keeps driving its last output value);
* :mod:`~firmware_sim.gpiod.sim_chip` -- ``SimChip``: drives inputs at
  virtual times (``schedule_input``, ``press``), debounces, detects edges and
  records every line's level history;
* :mod:`~firmware_sim.gpiod.kernel` -- ``GpioSim``: the simulated kernel
  (chips by path, one clock); ``GpioSim(clock).gpiod`` is the module-like
  object to inject into edge code in place of the real ``gpiod``::

    gsim = GpioSim(clock)
    chip = gsim.add_chip("/dev/gpiochip0", num_lines=54)
    gpiod = gsim.gpiod
    req = gpiod.request_lines("/dev/gpiochip0", config={17: gpiod.LineSettings(
        direction=gpiod.line.Direction.OUTPUT)}, consumer="heater")

Time is the shared :class:`firmware_sim.clock.VirtualClock`. Scheduled input
changes are applied at their exact scheduled times when the clock advances
past them, so edge-event timestamps do not depend on how coarsely the device
code sleeps. ``LineRequest.wait_edge_events`` advances the virtual clock (to
the next scheduled change, or to the timeout) instead of sleeping.

Debounce follows the kernel's software debouncer (gpiolib-cdev): a level
change is reported only once the line has been stable for the debounce
period, and the event is time-stamped at the end of that period.

This package namespace exports nothing itself: import each name from its module.
"""
