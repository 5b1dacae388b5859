"""The shipped default model bundle (installed as the package ``thermotouch_models``)."""

from pathlib import Path

DEFAULT_BUNDLE = Path(__file__).resolve().parent / "default"
