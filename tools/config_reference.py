"""Rewrite the config reference of docs/config.md from mpdem.config.SCHEMA.

    .venv/bin/python tools/config_reference.py

tests/test_config.py fails while the file and the schema disagree.
"""
from pathlib import Path

from mpdem.config import reference_markdown

doc = Path(__file__).parents[1] / "docs" / "config.md"
text = doc.read_text()
a, b = "<!-- config-reference -->", "<!-- /config-reference -->"
head, rest = text.split(a, 1)
_, tail = rest.split(b, 1)
doc.write_text(f"{head}{a}\n{reference_markdown()}\n{b}{tail}")
