"""PBD-AG HTTP service: FastAPI app, persistence, and the wire <-> domain codec."""
