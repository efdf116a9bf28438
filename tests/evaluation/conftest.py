"""Every test here runs the evaluation: without the `eval` extra each module skips."""

from tests.eval_extra import skip_modules_without_eval_extra as pytest_pycollect_makemodule

__all__ = ["pytest_pycollect_makemodule"]
