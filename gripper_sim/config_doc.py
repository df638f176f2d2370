"""Markdown table of every configuration key (``python -m gripper_sim.config_doc``).

Beside each key's built-in default the table lists the fruit presets' values where they
differ from it: without ``--fruit`` the default fruit's preset applies, so those are the
values a user actually gets.
"""
from __future__ import annotations

import json
from typing import Any

from gripper_sim.configuration import (DEFAULT_FRUIT, SCHEMA, available_fruits,
                                       load_config)

HEADER = ('| key | built-in default | fruit presets, where they differ | unit | range | '
          'meaning |')


def _range(spec) -> str:
    if spec.choices:
        return ', '.join(spec.choices)
    if spec.low is None and spec.high is None:
        return ''
    low = '' if spec.low is None else ('> ' if spec.open_low else '>= ') + f'{spec.low:g}'
    high = '' if spec.high is None else f'<= {spec.high:g}'
    return ', '.join(p for p in (low, high) if p)


def _shown(value: Any) -> str:
    """A configuration value as a user writes it in YAML (an outline as its size)."""
    if value is None:
        return 'null'
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f'{value:g}'
    if isinstance(value, str) and value.startswith('['):
        return f'an outline of {len(json.loads(value))} points'
    return str(value)


def _preset_values(fruits: list[str]) -> dict[str, str]:
    """Per key, the presets' values that differ from the built-in default, grouped by value
    (the default fruit's group first), e.g. ``30000 (apple, orange), 130000 (peach)``."""
    configs = {name: load_config(fruit=name) for name in fruits}
    cells = {}
    for key, spec in SCHEMA.items():
        groups: dict[str, list[str]] = {}
        for name, config in configs.items():
            if config[key] != spec.default:
                groups.setdefault(_shown(config[key]), []).append(name)
        ordered = sorted(groups.items(), key=lambda item: (DEFAULT_FRUIT not in item[1],
                                                           item[1][0]))
        if all([value] == names for value, names in ordered) and ordered:
            cells[key] = "each preset's own"
        else:
            cells[key] = ', '.join(f'{value} ({", ".join(names)})' for value, names in ordered)
    return cells


def markdown_table() -> str:
    """The table: one row per key of the schema, in the schema's order."""
    presets = _preset_values(available_fruits())
    lines = [HEADER, '|---|---|---|---|---|---|']
    for key, spec in SCHEMA.items():
        default = _shown(spec.default)
        if spec.default_3d is not None:
            default = f'{default} (3D: {_shown(spec.default_3d)})'
        lines.append(f'| `{key}` | {default} | {presets[key]} | {spec.unit} | '
                     f'{_range(spec)} | {spec.description} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    print(markdown_table())
