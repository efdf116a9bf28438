"""The evaluation: the paper's protocols on simulated streams, every method on identical batches.

Reads the simulator's streams and ground truth (`sim`) and runs the service's core; the simulator
never imports it.
"""
