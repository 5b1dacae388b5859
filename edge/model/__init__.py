"""Model bundles: the container, its array schema and the device's verified model store."""
