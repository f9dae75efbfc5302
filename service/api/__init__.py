"""The REST service: FastAPI app factory, auth and one router per resource (docs/api.md)."""
