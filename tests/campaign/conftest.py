"""Fixtures of the campaign tests: small specs on the cheap flexible-attitude simulator."""

from __future__ import annotations

from pathlib import Path

import pytest

from .spec_texts import BASE_SPEC


@pytest.fixture
def write_spec(tmp_path):
    """Write a spec text to tmp_path/<name>.toml and return its path."""

    def _write(text: str = BASE_SPEC, name: str = "spec") -> Path:
        path = tmp_path / f"{name}.toml"
        path.write_text(text)
        return path

    return _write
