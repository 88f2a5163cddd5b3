"""Rewrite the config reference of README.md from mpdem.config.SCHEMA.

    .venv/bin/python tools/readme_config.py
"""
from pathlib import Path

from mpdem.config import reference_markdown

readme = Path(__file__).parents[1] / "README.md"
text = readme.read_text()
a, b = "<!-- config-reference -->", "<!-- /config-reference -->"
head, rest = text.split(a, 1)
_, tail = rest.split(b, 1)
readme.write_text(f"{head}{a}\n{reference_markdown()}\n{b}{tail}")
