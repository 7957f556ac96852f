"""Source dataset readers. Each module turns one raw format into `Scenario`s."""

from scenariomax.sources.base import Failure, InputError, Source

__all__ = ["Failure", "InputError", "Source"]
