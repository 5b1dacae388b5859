"""The daemon: configuration, request handlers and their argument policy, the measurement worker,
model uploads, the default estimator and the process entry point."""
