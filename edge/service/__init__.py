"""The daemon: configuration, request handlers, uploads and the process entry point."""
