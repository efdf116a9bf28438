"""PBD-AG core: pure algorithms of the method (no SQL, no HTTP, no files, no clocks)."""
