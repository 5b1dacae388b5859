"""Register-level emulations of the board's I2C chips."""
