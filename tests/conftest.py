"""Shared test setup: model files come from ../shared/models (DEFACE_MODELS) when it is there."""

from __future__ import annotations

import os

import pytest

from deface.paths import shared_dir

_SHARED = shared_dir()
if _SHARED is not None:
    os.environ.setdefault("DEFACE_MODELS", str(_SHARED / "models"))


@pytest.fixture(scope="session")
def shared():
    """The shared/ folder (models, photos, clips); skips the test when it is absent."""
    if _SHARED is None:
        pytest.skip("../shared is not present")
    return _SHARED


@pytest.fixture(scope="session")
def photos(shared):
    return shared / "data" / "images"
