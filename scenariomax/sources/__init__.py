"""Source dataset readers. Each module turns one raw format into `Scenario`s."""

from scenariomax.errors import InputError
from scenariomax.sources.base import Failure, Source

__all__ = ["Failure", "InputError", "Source"]
