"""The wire <-> domain codec: between api_schema's models and core's records, for the service,
the simulator, the evaluation and any client that wants the service's own decoding (it never
imports the service, SQL or HTTP)."""
