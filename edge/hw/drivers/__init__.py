"""Device drivers: chips on the I2C bus, the heater and the trigger button."""
