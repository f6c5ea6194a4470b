"""Carry out docker/Dockerfile's steps in a Debian bookworm root, where no container engine runs.

The image's base, ``python:3.11-slim-bookworm``, is Debian bookworm with Python 3.11 as
``python`` and ``pip``: a root made by ``debootstrap`` with Debian's python3 (3.11) and a
virtual environment at ``/usr/local/py`` stands in for it. The script then follows the
Dockerfile line by line (ENV, WORKDIR, COPY with the build context filtered by
``docker/Dockerfile.dockerignore``, RUN in a chroot, VOLUME, ENTRYPOINT, CMD) and finally runs
the entry point with the arguments given, so the image's content is exercised as the
container would run it:

    python3 docker/check_rootfs.py /tmp/ucat-rootfs -- run --config /config/sim-devices.toml \
        --headless --duration 10 --mode baseline --velocity 0.2

Needs root, ``debootstrap`` (Debian package) and access to Debian's and PyPI's mirrors.
What it does not check: the base image itself, layer caching, the other architecture.
"""

from __future__ import annotations

import argparse
import fnmatch
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCKERFILE = REPO / "docker" / "Dockerfile"
IGNORE = REPO / "docker" / "Dockerfile.dockerignore"
BASE = "python:3.11-slim-bookworm"
PY = "/usr/local/py"  # stands in for the base image's /usr/local Python


def instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) in order, continuation lines joined, comments dropped."""
    out, pending = [], ""
    for line in path.read_text().splitlines():
        stripped = line.strip()
        if not pending and (not stripped or stripped.startswith("#")):
            continue
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        full = pending + stripped
        pending = ""
        word, _, rest = full.partition(" ")
        out.append((word.upper(), rest.strip()))
    return out


def ignored(rel: str, patterns: list[str]) -> bool:
    """Docker's rule, for the patterns this project uses: rooted at the context, ``**`` any depth."""
    parts = rel.split("/")
    for pattern in patterns:
        for i in range(1, len(parts) + 1):  # a pattern naming a folder excludes what is in it
            head = "/".join(parts[:i])
            if fnmatch.fnmatchcase(head, pattern) or (
                pattern.startswith("**/") and fnmatch.fnmatchcase(parts[i - 1], pattern[3:])
            ):
                return True
    return False


def context_files() -> list[str]:
    """The files of the build context: git's tracked files less the dockerignore patterns."""
    patterns = [p.strip() for p in IGNORE.read_text().splitlines()
                if p.strip() and not p.strip().startswith("#")]
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO, check=True, capture_output=True,
                             text=True).stdout.split()
    return [f for f in tracked if not ignored(f, patterns)]


def exec_form(args: str) -> list[str]:
    import json
    value = json.loads(args)
    if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
        raise SystemExit(f"{DOCKERFILE}: expected the exec form (a JSON list), got {args!r}")
    return value


class Root:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.env = {"PATH": f"{PY}/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
                    "HOME": "/root", "LANG": "C.UTF-8"}
        self.workdir = "/"
        self.mounts: list[Path] = []

    def make(self) -> None:
        if not (self.path / "usr" / "bin" / "python3").exists():
            subprocess.run(["debootstrap", "--variant=minbase",
                            "--include=python3,python3-venv,ca-certificates", "bookworm",
                            str(self.path), "http://deb.debian.org/debian"], check=True)
        # this machine's resolver and certificate authorities, as a build host's daemon would use
        for f in ("etc/resolv.conf", "etc/ssl/certs/ca-certificates.crt"):
            shutil.copy2(Path("/") / f, self.path / f)
        for fs in ("proc", "sys", "dev", "dev/pts"):
            target = self.path / fs
            subprocess.run(["mount", "--bind", f"/{fs}", str(target)], check=True)
            self.mounts.append(target)
        if not (self.path / PY.lstrip("/") / "bin" / "python").exists():
            self.run(f"python3 -m venv {PY}")

    def close(self) -> None:
        for target in reversed(self.mounts):
            subprocess.run(["umount", str(target)], check=False)

    def run(self, command: str | list[str]) -> int:
        argv = command if isinstance(command, list) else ["/bin/sh", "-c", command]
        shown = command if isinstance(command, str) else shlex.join(command)
        print(f"[{self.workdir}] {shown}", flush=True)
        inner = ["/bin/sh", "-c", f"cd {shlex.quote(self.workdir)} && exec \"$@\"", "sh", *argv]
        return subprocess.run(["chroot", str(self.path), "/usr/bin/env", "-i",
                               *(f"{k}={v}" for k, v in self.env.items()), *inner]).returncode

    def inside(self, path: str) -> Path:
        full = path if path.startswith("/") else f"{self.workdir.rstrip('/')}/{path}"
        return self.path / full.lstrip("/")

    def copy(self, src: str, dst: str, files: list[str]) -> None:
        src = src.rstrip("/")
        target = self.inside(dst)
        for f in files:
            if src == ".":
                rel = f
            elif f == src or f.startswith(src + "/"):
                rel = f[len(src) + 1:] if f != src else Path(f).name
            else:
                continue
            out = target / rel
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / f, out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root", type=Path, help="folder for the bookworm root (kept between runs)")
    parser.add_argument("args", nargs=argparse.REMAINDER,
                        help="after --: arguments for the entry point (default: the Dockerfile's CMD)")
    ns = parser.parse_args(argv)
    args = ns.args[1:] if ns.args[:1] == ["--"] else ns.args
    if os.geteuid() != 0:
        parser.error("needs root (debootstrap, mount, chroot)")
    steps = instructions(DOCKERFILE)
    if steps[0] != ("FROM", BASE):
        parser.error(f"{DOCKERFILE}: the base is {steps[0][1]!r}; this check stands in for {BASE} only")
    files = context_files()
    root = Root(ns.root.resolve())
    entrypoint: list[str] = []
    cmd: list[str] = []
    try:
        root.make()
        for word, rest in steps[1:]:
            if word == "ENV":
                for item in shlex.split(rest):
                    key, _, value = item.partition("=")
                    root.env[key] = value
            elif word == "WORKDIR":
                root.workdir = rest
                root.inside(rest).mkdir(parents=True, exist_ok=True)
            elif word == "COPY":
                src, dst = shlex.split(rest)
                root.copy(src, dst, files)
            elif word == "RUN":
                if (code := root.run(rest)) != 0:
                    print(f"RUN failed with exit status {code}: {rest}", file=sys.stderr)
                    return code
            elif word == "VOLUME":
                for v in exec_form(rest):
                    root.inside(v).mkdir(parents=True, exist_ok=True)
            elif word == "ENTRYPOINT":
                entrypoint = exec_form(rest)
            elif word == "CMD":
                cmd = exec_form(rest)
            else:
                parser.error(f"{DOCKERFILE}: {word} is not an instruction this check knows")
        return root.run(entrypoint + (args or cmd))
    finally:
        root.close()


if __name__ == "__main__":
    sys.exit(main())
