"""Regenerate the configuration key table in README.md from the schema and the presets."""
from pathlib import Path

from gripper_sim.config_doc import HEADER, markdown_table

readme = Path(__file__).resolve().parents[1] / 'README.md'
text = readme.read_text()
old_header = '| key | default | unit | range | meaning |'
start = text.index(HEADER) if HEADER in text else text.index(old_header)
end = text.index('\n\n', start)
readme.write_text(text[:start] + markdown_table() + text[end:])
