"""Browser tests of the pages the service serves."""
