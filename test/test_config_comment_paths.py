"""The source files the comments of config/**/*.yaml point a reader to exist (the
scenario file named gripper_sim/core/scenario.py after the schema had moved to
workflows/)."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCE_PATH = re.compile(r'gripper_sim/[\w/]+\.py')


def test_every_source_path_named_in_a_config_comment_exists():
    named = {(path.relative_to(ROOT), match)
             for path in sorted((ROOT / 'config').rglob('*.yaml'))
             for line in path.read_text(encoding='utf-8').splitlines()
             if line.lstrip().startswith('#') or ' #' in line
             for match in SOURCE_PATH.findall(line)}
    assert named, 'no config comment names a source file: the check checks nothing'
    missing = sorted(f'{where}: {name}' for where, name in named if not (ROOT / name).exists())
    assert not missing
