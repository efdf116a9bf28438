"""The store: event log, projections, snapshots, job queue and blobs."""
