"""Regenerate the configuration key table and the glossary in README.md from the schema,
the presets and the vocabulary (``gripper_sim.core.vocabulary``)."""
from pathlib import Path

from gripper_sim.config_doc import HEADER, markdown_table
from gripper_sim.core.vocabulary import GLOSSARY_HEADER, markdown_glossary


def replace_block(text: str, header: str, block: str) -> str:
    """``text`` with the Markdown block that starts with ``header`` (up to the first
    blank line after its last table) replaced by ``block``."""
    start = text.index(header)
    end = start
    for _ in range(block.count('\n\n') + 1):
        end = text.index('\n\n', end + 2) if _ else text.index('\n\n', start)
    return text[:start] + block + text[end:]


readme = Path(__file__).resolve().parents[1] / 'README.md'
text = readme.read_text()
text = replace_block(text, HEADER, markdown_table())
text = replace_block(text, GLOSSARY_HEADER, markdown_glossary())
readme.write_text(text)
