"""Markdown table of every configuration key (``python -m gripper_sim.config_doc``)."""
from __future__ import annotations

from gripper_sim.configuration import SCHEMA


def _range(spec) -> str:
    if spec.choices:
        return ', '.join(spec.choices)
    if spec.low is None and spec.high is None:
        return ''
    low = '' if spec.low is None else ('> ' if spec.open_low else '>= ') + f'{spec.low:g}'
    high = '' if spec.high is None else f'<= {spec.high:g}'
    return ', '.join(p for p in (low, high) if p)


def markdown_table() -> str:
    lines = ['| key | default | unit | range | meaning |', '|---|---|---|---|---|']
    for key, spec in SCHEMA.items():
        default = 'null' if spec.default is None else spec.default
        if spec.default_3d is not None:
            default = f'{default} (3D: {spec.default_3d})'
        lines.append(f'| `{key}` | {default} | {spec.unit} | {_range(spec)} | '
                     f'{spec.description} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    print(markdown_table())
