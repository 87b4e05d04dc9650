#!/usr/bin/env python3
"""Static checks of docker/Dockerfile and docker/compose.yaml (no Docker engine needed).

    python3 scripts/check_docker.py [--root REPO]

Prints one line per check, `ok` or `FAIL` with every fault it found, and exits 1 when any check
fails. It checks that
  - every FROM is pinned: a digest (@sha256:...) or a dated tag, or an earlier stage;
  - every apt install names `package=version`, those pins equal docker/apt-versions.txt (both
    ways), and the ROS snapshot the image installs from is the list's, a date;
  - every pip install is the project's resolve: -r requirements/requirements.txt (or a file
    filtered from it in the same RUN) with -c requirements/constraints.txt, any `name==version`
    agreeing with constraints.txt; requirements.txt's own pins agree with constraints.txt, and
    scripts/setup.sh installs the same two files;
  - compose has the profiles twin, cell and mocap, each service a profile, and every service with
    host networking has ipc: host;
  - every service's command is `ros2 run <package> <executable>` of a workspace package's
    console_scripts (or of an apt package the service's image installs, KNOWN_APT_EXECUTABLES),
    with a --params-file that resolves (through the service's volumes, the image's COPY lines or
    the workspace install) to a file in the repository;
  - DDS: Fast DDS everywhere; the twin profile on loopback (LOCALHOST discovery, a profile whose
    UDP whitelist is 127.0.0.1 only), the other profiles on the LAN (SUBNET discovery, a profile
    that whitelists a cell address); FASTDDS_ and FASTRTPS_DEFAULT_PROFILES_FILE equal;
    ROS_DOMAIN_ID from the environment with a default; the twin only in the twin profile.
Standard library and PyYAML only. tests/test_docker.py runs it on the repository and on broken copies.
"""

from __future__ import annotations

import argparse
import ast
import fnmatch
import re
import shlex
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import yaml

DOCKERFILE = 'docker/Dockerfile'
COMPOSE = 'docker/compose.yaml'
APT_VERSIONS = 'docker/apt-versions.txt'
REQUIREMENTS = 'requirements/requirements.txt'
CONSTRAINTS = 'requirements/constraints.txt'
SETUP_SH = 'scripts/setup.sh'
WORKSPACE = 'ros_ws/src'
PROFILES = ('twin', 'cell', 'mocap')
LOOPBACK_PROFILE = 'twin'
# Executables of apt ROS packages a compose service may run (not in the workspace, so not
# readable from a setup.py here): vrpn_mocap's CMakeLists.txt installs client_node.
KNOWN_APT_EXECUTABLES = {'vrpn_mocap': {'client_node'}}
DIGEST = re.compile(r'@sha256:[0-9a-f]{64}$')
DATED_TAG = re.compile(r':[^/@]*(19|20)\d\d-?[01]\d-?[0-3]\d')
DATE = re.compile(r'^(19|20)\d\d-[01]\d-[0-3]\d$')
DOMAIN_ID = re.compile(r'^\$\{ROS_DOMAIN_ID:?-\d+\}$')


def norm(name: str) -> str:
    """A Python distribution's normalized name (PEP 503)."""
    return re.sub(r'[-_.]+', '-', name).lower()


def interpolate(text: str) -> str:
    """Compose's ${VAR:-default} / ${VAR-default} / ${VAR} / $VAR, with every variable unset: the
    defaults are what the checked files ship with."""
    text = re.sub(r'\$\{[A-Za-z_][A-Za-z0-9_]*:?-([^}]*)\}', r'\1', text)
    text = re.sub(r'\$\{[A-Za-z_][A-Za-z0-9_]*[:?][^}]*\}', '', text)
    text = re.sub(r'\$\{[A-Za-z_][A-Za-z0-9_]*\}', '', text)
    return re.sub(r'\$[A-Za-z_][A-Za-z0-9_]*', '', text)


def pins(path: Path) -> dict[str, str]:
    """`name==version` lines of a requirements file, by normalized name."""
    out = {}
    for line in path.read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if '==' in line:
            name, version = line.split('==', 1)
            out[norm(re.sub(r'\[.*\]', '', name).strip())] = version.strip()
    return out


# --- the Dockerfile ------------------------------------------------------------------------------

@dataclass
class Stage:
    name: str
    base: str
    line: int
    parent: Stage | None = None
    env: dict[str, str] = field(default_factory=dict)
    args: dict[str, str] = field(default_factory=dict)
    workdir: str = '/'
    copies: list[tuple[str, str]] = field(default_factory=list)   # (repo source, absolute destination)
    apt: dict[str, str] = field(default_factory=dict)             # package -> version ('' = unpinned)

    def all_env(self) -> dict[str, str]:
        return {**(self.parent.all_env() if self.parent else {}), **self.env}

    def all_copies(self) -> list[tuple[str, str]]:
        return (self.parent.all_copies() if self.parent else []) + self.copies

    def all_apt(self) -> dict[str, str]:
        return {**(self.parent.all_apt() if self.parent else {}), **self.apt}


def instructions(text: str) -> list[tuple[int, str, str]]:
    """(line, KEYWORD, arguments) of a Dockerfile: comment lines dropped, continuations joined."""
    out, parts, start = [], [], 0
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith('#'):
            continue
        if not parts:
            if not line.strip():
                continue
            start = number
        if line.rstrip().endswith('\\'):
            parts.append(line.rstrip()[:-1])
            continue
        parts.append(line)
        joined = ' '.join(p.strip() for p in parts)
        parts = []
        keyword, _, rest = joined.partition(' ')
        out.append((start, keyword.upper(), rest.strip()))
    return out


def commands(run: str) -> list[list[str]]:
    """The simple commands of a RUN line, each as words."""
    out = []
    for segment in re.split(r'&&|\|\||;|\||\n', run):
        try:
            words = shlex.split(segment)
        except ValueError:
            words = segment.split()
        while words and words[0] in ('then', 'else', 'do', 'if', '!', 'sudo'):
            words = words[1:]
        if words:
            out.append(words)
    return out


def key_values(text: str) -> dict[str, str]:
    """ENV / ARG arguments: `A=1 B="two"` or the legacy `A 1`."""
    words = shlex.split(text)
    if words and '=' not in words[0]:
        return {words[0]: ' '.join(words[1:])}
    return dict(w.split('=', 1) if '=' in w else (w, '') for w in words)


@dataclass
class Dockerfile:
    stages: list[Stage]
    global_args: dict[str, str]
    pip_runs: list[tuple[int, str]]     # (line, RUN text) of RUNs that pip install


def parse_dockerfile(path: Path) -> Dockerfile:
    stages: list[Stage] = []
    global_args: dict[str, str] = {}
    pip_runs = []
    for line, keyword, rest in instructions(path.read_text()):
        stage = stages[-1] if stages else None
        if keyword == 'ARG':
            (stage.args if stage else global_args).update(key_values(rest))
        elif keyword == 'FROM':
            words = rest.split()
            base = words[0]
            for name, value in global_args.items():
                base = base.replace('${' + name + '}', value).replace('$' + name, value)
            name = words[2] if len(words) >= 3 and words[1].upper() == 'AS' else str(len(stages))
            parent = next((s for s in stages if s.name == base), None)
            stages.append(Stage(name, base, line, parent, workdir=parent.workdir if parent else '/'))
        elif stage is None:
            continue
        elif keyword == 'ENV':
            stage.env.update(key_values(rest))
        elif keyword == 'WORKDIR':
            stage.workdir = str(PurePosixPath(stage.workdir) / rest)
        elif keyword in ('COPY', 'ADD'):
            words = [w for w in rest.split() if not w.startswith('--')]
            if len(words) >= 2:
                dest = str(PurePosixPath(stage.workdir) / words[-1])
                stage.copies.extend((src, dest) for src in words[:-1])
        elif keyword == 'RUN':
            for words in commands(rest):
                tool = PurePosixPath(words[0]).name
                if tool in ('apt-get', 'apt') and 'install' in words:
                    for word in words[words.index('install') + 1:]:
                        if not word.startswith('-'):
                            package, _, version = word.partition('=')
                            stage.apt[package] = version
            if re.search(r'\bpip3?\s+install\b|-m\s+pip\s+install\b', rest):
                pip_runs.append((line, rest))
    return Dockerfile(stages, global_args, pip_runs)


def check_base_images(df: Dockerfile) -> list[str]:
    problems = []
    names = set()
    for stage in df.stages:
        if stage.parent is None and not (DIGEST.search(stage.base) or DATED_TAG.search(stage.base)):
            problems.append(f'line {stage.line}: FROM {stage.base} is a floating tag (pin a digest @sha256:... '
                            'or a dated tag)')
        names.add(stage.name)
    if not df.stages:
        problems.append('no FROM')
    return problems


def read_apt_versions(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line:
            name, _, version = line.split()[0].partition('=')
            out[name] = version
    return out


def check_apt(df: Dockerfile, root: Path) -> tuple[list[str], list[str]]:
    """(unpinned packages, disagreements with docker/apt-versions.txt)."""
    unpinned = [f'apt package {pkg} has no version (stage {s.name}): write {pkg}=<version>'
                for s in df.stages for pkg, version in s.apt.items() if not version]
    listed_path = root / APT_VERSIONS
    if not listed_path.is_file():
        return unpinned, [f'{APT_VERSIONS} is missing']
    listed = read_apt_versions(listed_path)
    snapshot = listed.pop('ROS_SNAPSHOT', None)
    installed: dict[str, str] = {}
    for stage in df.stages:
        installed.update({p: v for p, v in stage.apt.items() if v})
    disagree = []
    for pkg, version in sorted(installed.items()):
        if pkg not in listed:
            disagree.append(f'apt package {pkg}={version} is not in {APT_VERSIONS}')
        elif listed[pkg] != version:
            disagree.append(f'apt package {pkg}: the Dockerfile pins {version}, {APT_VERSIONS} says {listed[pkg]}')
    for pkg in sorted(set(listed) - set(installed) - {p for s in df.stages for p in s.apt}):
        disagree.append(f'{APT_VERSIONS} lists {pkg}, which the Dockerfile does not install')
    arg = next((s.args['ROS_SNAPSHOT'] for s in df.stages if 'ROS_SNAPSHOT' in s.args), None)
    arg = arg if arg is not None else df.global_args.get('ROS_SNAPSHOT')
    if snapshot is None or not DATE.match(snapshot):
        disagree.append(f'{APT_VERSIONS} names no dated ROS_SNAPSHOT (YYYY-MM-DD)')
    elif arg != snapshot:
        disagree.append(f'the Dockerfile\'s ARG ROS_SNAPSHOT={arg} differs from {APT_VERSIONS}\'s {snapshot}')
    return unpinned, disagree


PIP_VALUE_OPTIONS = {'-r', '--requirement', '-c', '--constraint', '-i', '--index-url', '--extra-index-url',
                     '-f', '--find-links', '-t', '--target', '--prefix', '--root', '-e', '--editable',
                     '--python-version', '--platform', '--report', '--progress-bar'}


def check_pip(df: Dockerfile, root: Path) -> list[str]:
    problems = []
    constraints = pins(root / CONSTRAINTS)
    requirements = pins(root / REQUIREMENTS)
    for line, run in df.pip_runs:
        derived = {m.group(2) for m in re.finditer(r'grep\s+-v[^>;&]*?(\S*' + re.escape(REQUIREMENTS)
                                                   + r')\s*>\s*(\S+)', run)}
        for words in commands(run):
            if 'install' not in words or not any(PurePosixPath(w).name in ('pip', 'pip3') for w in words):
                continue
            args = words[words.index('install') + 1:]
            reqs, cons, specs = [], [], []
            i = 0
            while i < len(args):
                word = args[i]
                option, eq, value = word.partition('=')
                if option in PIP_VALUE_OPTIONS:
                    if not eq:
                        i += 1
                        value = args[i] if i < len(args) else ''
                    if option in ('-r', '--requirement'):
                        reqs.append(value)
                    elif option in ('-c', '--constraint'):
                        cons.append(value)
                elif not word.startswith('-'):
                    specs.append(word)
                i += 1
            where = f'line {line}: pip install'
            if not any(c.endswith(CONSTRAINTS) for c in cons):
                problems.append(f'{where} without -c {CONSTRAINTS}')
            for req in reqs:
                if not (req.endswith(REQUIREMENTS) or req in derived):
                    problems.append(f'{where} -r {req}: neither {REQUIREMENTS} nor filtered from it in this RUN')
            for spec in specs:
                name, sep, version = spec.partition('==')
                key = norm(re.sub(r'\[.*\]', '', name))
                if not sep:
                    problems.append(f'{where} {spec}: not pinned (name==version from {CONSTRAINTS})')
                elif version not in (constraints.get(key), requirements.get(key)):
                    problems.append(f'{where} {spec}: {CONSTRAINTS} pins {key}=={constraints.get(key)}')
    return problems


def check_project_resolve(root: Path) -> list[str]:
    """requirements.txt's pins agree with constraints.txt, and setup.sh installs those two files."""
    problems = []
    constraints = pins(root / CONSTRAINTS)
    for name, version in pins(root / REQUIREMENTS).items():
        if name not in constraints:
            problems.append(f'{REQUIREMENTS} pins {name}=={version}, {CONSTRAINTS} has no {name}')
        elif constraints[name].split('+')[0] != version.split('+')[0]:
            problems.append(f'{REQUIREMENTS} pins {name}=={version}, {CONSTRAINTS} {constraints[name]}')
    setup = (root / SETUP_SH).read_text()
    if not (re.search(r'^REQ="' + re.escape(REQUIREMENTS) + '"', setup, re.M)
            and re.search(r'^CON="' + re.escape(CONSTRAINTS) + '"', setup, re.M)
            and re.search(r'pip install -r "\$REQ" -c "\$CON"', setup)):
        problems.append(f'{SETUP_SH} no longer installs -r {REQUIREMENTS} -c {CONSTRAINTS}')
    return problems


# --- compose -------------------------------------------------------------------------------------

def console_scripts(setup_py: Path) -> set[str]:
    """The console_scripts names of a setup.py (read, not run)."""
    names = set()
    for node in ast.walk(ast.parse(setup_py.read_text())):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts' and isinstance(value, ast.List):
                    names.update(e.value.split('=')[0].strip() for e in value.elts if isinstance(e, ast.Constant))
    return names


@dataclass
class Service:
    name: str
    raw: dict
    stage: Stage | None
    profiles: list[str]
    env: dict[str, str]          # the image's ENV, then the service's environment (raw values)
    volumes: list[tuple[str, str]]
    words: list[str]             # the command, interpolated


def service_env(raw) -> dict[str, str]:
    env = raw.get('environment') or {}
    if isinstance(env, list):
        env = dict(item.split('=', 1) if '=' in item else (item, '') for item in env)
    return {k: '' if v is None else str(v) for k, v in env.items()}


def service_volumes(raw) -> list[tuple[str, str]]:
    out = []
    for volume in raw.get('volumes') or []:
        if isinstance(volume, dict):
            out.append((str(volume.get('source', '')), str(volume.get('target', ''))))
        else:
            parts = interpolate(str(volume)).split(':')
            if len(parts) >= 2:
                out.append((parts[0], parts[1]))
    return out


def load_services(compose: dict, df: Dockerfile) -> tuple[list[Service], list[str]]:
    problems = []
    stages = {s.name: s for s in df.stages}
    by_image = {}
    for name, raw in (compose.get('services') or {}).items():
        build = raw.get('build')
        if build is not None and raw.get('image'):
            target = build.get('target') if isinstance(build, dict) else None
            by_image[raw['image']] = stages.get(target) if target else (df.stages[-1] if df.stages else None)
    services = []
    for name, raw in (compose.get('services') or {}).items():
        build = raw.get('build')
        if build is not None:
            target = build.get('target') if isinstance(build, dict) else None
            stage = stages.get(target) if target else (df.stages[-1] if df.stages else None)
            if target and stage is None:
                problems.append(f'{name}: build target {target} is no stage of {DOCKERFILE}')
        else:
            stage = by_image.get(raw.get('image'))
            if stage is None:
                problems.append(f'{name}: image {raw.get("image")} is built by no service from {DOCKERFILE}')
        command = raw.get('command') or ''
        words = ([interpolate(str(w)) for w in command] if isinstance(command, list)
                 else shlex.split(interpolate(str(command))))
        env = {**(stage.all_env() if stage else {}), **service_env(raw)}
        services.append(Service(name, raw, stage, list(raw.get('profiles') or []), env, service_volumes(raw), words))
    return services, problems


def resolve(service: Service, container_path: str, root: Path, compose_dir: Path) -> Path | None:
    """The repository file behind a path inside a service's container, or None."""
    path = PurePosixPath(container_path)
    for source, target in service.volumes:
        if path == PurePosixPath(target) or PurePosixPath(target) in path.parents:
            rest = path.relative_to(target)
            return (compose_dir / source / rest).resolve()
    match = re.match(r'^/rad/ros_ws/install/([^/]+)/share/\1/(.+)$', container_path)
    copies = service.stage.all_copies() if service.stage else []
    if match and any(dest == '/rad/ros_ws/src' for _, dest in copies):
        package, rest = match.groups()
        setup = root / WORKSPACE / package / 'setup.py'
        if setup.is_file():
            patterns = re.findall(r"glob\('([^']+)'\)", setup.read_text())
            if any(fnmatch.fnmatch(rest, p) for p in patterns) or rest == 'package.xml':
                return (root / WORKSPACE / package / rest).resolve()
        return None
    for source, dest in copies:
        if path == PurePosixPath(dest) or PurePosixPath(dest) in path.parents:
            return (root / source / path.relative_to(dest)).resolve()
    return None


def inside(path: Path | None, root: Path) -> bool:
    return path is not None and path.is_file() and root.resolve() in path.parents


def check_compose_commands(services: list[Service], root: Path, compose_dir: Path) -> tuple[list[str], list[str]]:
    """(executable problems, params file problems)."""
    exe_problems, params_problems = [], []
    for s in services:
        words = s.words
        if words[:2] != ['ros2', 'run'] or len(words) < 4:
            exe_problems.append(f'{s.name}: command is not `ros2 run <package> <executable> ...`: {" ".join(words)}')
            continue
        package, exe = words[2], words[3]
        setup = root / WORKSPACE / package / 'setup.py'
        if setup.is_file():
            if exe not in console_scripts(setup):
                exe_problems.append(f'{s.name}: {package} has no executable {exe} (console_scripts of '
                                    f'{WORKSPACE}/{package}/setup.py)')
        elif package in KNOWN_APT_EXECUTABLES:
            deb = 'ros-jazzy-' + package.replace('_', '-')
            if exe not in KNOWN_APT_EXECUTABLES[package]:
                exe_problems.append(f'{s.name}: {package} has no executable {exe}')
            if not s.stage or deb not in s.stage.all_apt():
                exe_problems.append(f'{s.name}: runs {package}, but its image (stage '
                                    f'{s.stage.name if s.stage else "?"}) does not apt install {deb}')
        else:
            exe_problems.append(f'{s.name}: unknown package {package} (no {WORKSPACE}/{package}/setup.py)')
        files = [words[i + 1] for i, w in enumerate(words[:-1]) if w == '--params-file']
        if not files:
            params_problems.append(f'{s.name}: no --params-file')
        for file in files:
            if not inside(resolve(s, file, root, compose_dir), root):
                params_problems.append(f'{s.name}: params file {file} is no file of the repository '
                                       '(through its volumes, the image\'s COPY or the workspace install)')
    return exe_problems, params_problems


def whitelist(profile: Path) -> set[str]:
    addresses = set()
    for element in ET.parse(profile).iter():
        if element.tag.split('}')[-1] == 'interfaceWhiteList':
            addresses.update((a.text or '').strip() for a in element if a.tag.split('}')[-1] == 'address')
    return addresses


def check_dds(services: list[Service], root: Path, compose_dir: Path) -> list[str]:
    problems = []
    for s in services:
        loopback = LOOPBACK_PROFILE in s.profiles
        want_range = 'LOCALHOST' if loopback else 'SUBNET'
        env = s.env
        if env.get('RMW_IMPLEMENTATION') != 'rmw_fastrtps_cpp':
            problems.append(f'{s.name}: RMW_IMPLEMENTATION is {env.get("RMW_IMPLEMENTATION")}, not rmw_fastrtps_cpp '
                            '(the profiles are Fast DDS XML)')
        if env.get('ROS_AUTOMATIC_DISCOVERY_RANGE') != want_range:
            problems.append(f'{s.name}: ROS_AUTOMATIC_DISCOVERY_RANGE is {env.get("ROS_AUTOMATIC_DISCOVERY_RANGE")}, '
                            f'not {want_range} ({"loopback" if loopback else "LAN"} profile {s.profiles})')
        if not DOMAIN_ID.match(str(s.raw.get('environment', {}).get('ROS_DOMAIN_ID', ''))
                               if isinstance(s.raw.get('environment'), dict) else ''):
            problems.append(f'{s.name}: ROS_DOMAIN_ID is not taken from the environment with a default '
                            '(${ROS_DOMAIN_ID:-42})')
        rtps, dds = env.get('FASTRTPS_DEFAULT_PROFILES_FILE'), env.get('FASTDDS_DEFAULT_PROFILES_FILE')
        if rtps != dds:
            problems.append(f'{s.name}: FASTRTPS_DEFAULT_PROFILES_FILE ({rtps}) and FASTDDS_DEFAULT_PROFILES_FILE '
                            f'({dds}) differ')
        if not rtps:
            problems.append(f'{s.name}: no FASTRTPS_DEFAULT_PROFILES_FILE')
            continue
        profile = resolve(s, rtps, root, compose_dir)
        if not inside(profile, root):
            problems.append(f'{s.name}: the Fast DDS profile {rtps} is no file of the repository')
            continue
        try:
            addresses = whitelist(profile)
        except ET.ParseError as error:
            problems.append(f'{s.name}: {profile.relative_to(root.resolve())}: {error}')
            continue
        shown = profile.relative_to(root.resolve())
        if loopback and addresses != {'127.0.0.1'}:
            problems.append(f'{s.name}: {shown} is not a loopback profile (whitelist {sorted(addresses)})')
        if not loopback and not (addresses - {'127.0.0.1', ''}):
            problems.append(f'{s.name}: {shown} is not a LAN profile (no cell address in its whitelist)')
    return problems


# --- main ----------------------------------------------------------------------------------------

def run_checks(root: Path) -> list[tuple[str, list[str]]]:
    """(check, problems) of every check, in order."""
    results: list[tuple[str, list[str]]] = []
    df = parse_dockerfile(root / DOCKERFILE)
    results.append(('Dockerfile: base images pinned (digest or dated tag)', check_base_images(df)))
    unpinned, disagree = check_apt(df, root)
    results.append(('Dockerfile: every apt package pinned (package=version)', unpinned))
    results.append((f'Dockerfile: apt pins and ROS snapshot = {APT_VERSIONS}', disagree))
    no_pip = [] if df.pip_runs else ['no pip install of the project\'s requirements']
    results.append((f'Dockerfile: pip installs = {REQUIREMENTS} -c {CONSTRAINTS}', no_pip + check_pip(df, root)))
    results.append(('requirements: pins agree with constraints.txt, as setup.sh installs them',
                    check_project_resolve(root)))

    compose = yaml.safe_load((root / COMPOSE).read_text()) or {}
    compose_dir = (root / COMPOSE).parent
    services, load_problems = load_services(compose, df)
    have = {p for s in services for p in s.profiles}
    results.append((f'compose: profiles {", ".join(PROFILES)}; every service in one',
                    [f'no service in profile {p}' for p in PROFILES if p not in have]
                    + [f'{s.name}: no profile' for s in services if not s.profiles] + load_problems))
    results.append(('compose: host networking has ipc: host',
                    [f'{s.name}: network_mode host without ipc: host' for s in services
                     if s.raw.get('network_mode') == 'host' and s.raw.get('ipc') != 'host']))
    exe_problems, params_problems = check_compose_commands(services, root, compose_dir)
    results.append(('compose: every command runs an executable that exists', exe_problems))
    results.append(('compose: every command has a params file of the repository', params_problems))
    results.append(('compose: DDS loopback for twin, LAN for cell and mocap', check_dds(services, root, compose_dir)))
    twin_nodes = [s for s in services if s.words[2:4] == ['rad_sim', 'twin_node']]
    results.append(('compose: the twin runs in the twin profile only',
                    [f'{s.name}: runs the twin in profiles {s.profiles}' for s in twin_nodes
                     if set(s.profiles) != {LOOPBACK_PROFILE}]
                    + ([] if twin_nodes else ['no service runs rad_sim twin_node'])))
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--root', type=Path, default=Path(__file__).resolve().parent.parent,
                        help='the repository root (default: this script\'s)')
    root = parser.parse_args(argv).root
    try:
        results = run_checks(root)
    except (OSError, yaml.YAMLError, SyntaxError) as error:
        print(f'FAIL  check_docker: cannot read the files: {error}')
        return 1
    failed = []
    for name, problems in results:
        if problems:
            failed.append(name)
            print(f'FAIL  {name}:')
            for problem in problems:
                print(f'        {problem}')
        else:
            print(f'ok    {name}')
    if failed:
        print(f'check_docker: {len(failed)} of {len(results)} checks failed: {"; ".join(failed)}')
        return 1
    print(f'check_docker: all {len(results)} checks passed')
    return 0


if __name__ == '__main__':
    sys.exit(main())
