"""Performance benchmarks: render + detect, decide + evolve, and the store's append and as_of."""
