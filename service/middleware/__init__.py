"""Pure ASGI middleware of the service, one per module."""
