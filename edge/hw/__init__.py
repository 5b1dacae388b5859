"""Hardware: the Board Protocol, sysfs PWM, register descriptors, sensor faults and the chip drivers (I/O only)."""
