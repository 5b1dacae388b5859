"""ThermoTouch host: material library, training, export, deployment and the user CLI."""
