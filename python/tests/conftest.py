"""Helpers shared by the Python tests: what a test needs that a machine may lack.

A test that needs lavapipe (or another Vulkan adapter) or an optional Python package such
as Mitsuba 3 asks for it here. Under `CI=true` (what CI services set) a missing dependency
fails the test, so that no skip hides it there; elsewhere the test is skipped and says
why (`pytest -rs` prints the reasons).
"""

import importlib
import os
from types import ModuleType

import pytest


def in_ci() -> bool:
    """Whether the tests run under CI (`CI=true`, as GitHub Actions, GitLab CI and others set)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def missing(reason: str) -> None:
    """A dependency is missing: fail under CI, skip elsewhere, saying why."""
    if in_ci():
        pytest.fail(f"{reason} (CI=true: a missing dependency fails instead of skipping)", pytrace=False)
    pytest.skip(reason)


def require_module(name: str, hint: str = "") -> ModuleType:
    """The module `name`, or a failure under CI / a skip elsewhere if it cannot be imported."""
    try:
        return importlib.import_module(name)
    except ImportError as e:
        missing(f"{name} cannot be imported ({e}){'; ' + hint if hint else ''}")
        raise  # not reached: missing() raises


def require_gpu() -> str:
    """The name of the Vulkan adapter the GPU backend opens (lavapipe in CI), or a failure
    under CI / a skip elsewhere if there is none."""
    import bsdfit

    available, name_or_why = bsdfit.gpu_available()
    if not available:
        missing(f"the GPU backend cannot start: {name_or_why}")
    return name_or_why
