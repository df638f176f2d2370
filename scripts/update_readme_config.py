"""Regenerate the configuration key table in README.md from the schema."""
from pathlib import Path

from gripper_sim.config_doc import markdown_table

readme = Path(__file__).resolve().parents[1] / 'README.md'
text = readme.read_text()
start = text.index('| key | default | unit | range | meaning |')
end = text.index('\n\n', start)
readme.write_text(text[:start] + markdown_table() + text[end:])
