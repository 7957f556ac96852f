"""Errors raised while parsing AV2 files; the source turns them into InputError / Failure."""

from __future__ import annotations


class Av2FormatError(ValueError):
    """A raw AV2 file does not have the structure the format promises (one-line message)."""


class Av2ScenarioError(ValueError):
    """One scenario cannot be built (e.g. no AV track); the run records a Failure and goes on."""
