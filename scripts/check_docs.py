#!/usr/bin/env python3
"""Runs every code block of the READMEs, as a reader would copy it.

    scripts/check_docs.py [--python PY] [--hbn BIN] [FILE.md ...]
        (default: README.md, ARCHITECTURE.md, CONTRIBUTING.md, hbn-py/README.md, docs/*.md)
    scripts/check_docs.py --self-test

Fenced blocks by language:

- ``sh``/``bash``/``shell``: run by ``bash -euo pipefail`` in a fresh temporary directory, with
  the directory of ``--hbn`` (default ``target/release/hbn``) first on ``PATH``;
- ``python``: run by ``--python`` (default: this interpreter) from the repository root, where the
  fixtures are;
- ``rust``: run as doctests of the ``hbn`` crate (``src/lib.rs`` includes ``README.md``;
  ``cargo test --doc -p hbn``); checked here only to be covered;
- ``text``: output or formulas, not run.

A block whose command is run elsewhere (the test suite itself, a wheel install, the minute-long
demo) is marked by an HTML comment right before it, ``<!-- check-docs: skip: WHY -->``, where
WHY names what runs or checks it. Any other block, a block without a language, or an indented
code block fails the check. Exit status 1 when a block fails.
"""

import argparse
import contextlib
import io
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHELLS = {"sh", "bash", "shell"}
# Markdown files whose ```rust blocks are doctests, and the file that includes them.
# What every run checks: the READMEs, the maintainers' pages and every page under docs/.
DEFAULT_FILES = ["README.md", "ARCHITECTURE.md", "CONTRIBUTING.md", "hbn-py/README.md"] + sorted(
    str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")
)
DOCTESTED = {"README.md": ("src/lib.rs", 'include_str!("../README.md")')}


class Block:
    def __init__(self, path, line, lang, code, marker):
        self.path, self.line, self.lang, self.code, self.marker = path, line, lang, code, marker

    def where(self):
        return f"{self.path}:{self.line}"


def blocks(path, text):
    """Fenced code blocks with the marker comment right before each; indented blocks are
    returned with lang None and an error."""
    out, errors = [], []
    lines = text.split("\n")
    i = 0
    pending = None  # (marker text, line index after the comment)
    prev_blank = True
    while i < len(lines):
        line = lines[i]
        m = re.match(r"^(\s*)```\s*([\w+-]*)\s*$", line)
        if m:
            indent, lang = m.group(1), m.group(2)
            start = i + 1
            j = start
            while j < len(lines) and not re.match(r"^\s*```\s*$", lines[j]):
                j += 1
            if j == len(lines):
                errors.append(f"{path}:{i + 1}: unclosed code block")
                break
            code = "\n".join(l[len(indent):] if l.startswith(indent) else l for l in lines[start:j])
            marker = pending[0] if pending and pending[1] == i else None
            out.append(Block(path, i + 1, lang or None, code + "\n", marker))
            pending = None
            i = j + 1
            prev_blank = False
            continue
        c = re.match(r"^\s*<!--\s*check-docs:(.*)$", line)
        if c:
            body = [c.group(1)]
            j = i
            while "-->" not in lines[j]:
                j += 1
                if j == len(lines):
                    errors.append(f"{path}:{i + 1}: unclosed check-docs comment")
                    return out, errors
                body.append(lines[j])
            text_ = " ".join(b.strip() for b in body).split("-->")[0].strip()
            # The marker applies to a block that follows directly (blank lines allowed).
            k = j + 1
            while k < len(lines) and not lines[k].strip():
                k += 1
            pending = (text_, k)
            i = j + 1
            continue
        if line.startswith("    ") and line.strip() and prev_blank:
            errors.append(
                f"{path}:{i + 1}: an indented code block; use a fenced block with a language"
            )
        prev_blank = not line.strip()
        i += 1
    return out, errors


def run_block(b, args):
    if b.lang in SHELLS:
        env = dict(os.environ)
        env["PATH"] = f"{Path(args.hbn).resolve().parent}{os.pathsep}{env.get('PATH', '')}"
        with tempfile.TemporaryDirectory(prefix="check-docs-") as d:
            r = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", b.code], cwd=d, env=env,
                capture_output=True, text=True,
            )
    elif b.lang == "python":
        r = subprocess.run(
            [args.python, "-c", b.code], cwd=ROOT, capture_output=True, text=True,
        )
    else:
        raise AssertionError(b.lang)
    return r.returncode, r.stdout + r.stderr


def check(files, args):
    failures = 0
    for f in files:
        path = Path(f)
        rel = path.resolve().relative_to(ROOT) if path.resolve().is_relative_to(ROOT) else path
        found, errors = blocks(str(rel), path.read_text())
        for e in errors:
            print(f"FAIL {e}")
            failures += 1
        for b in found:
            if b.lang == "text":
                print(f"text {b.where()}: not code")
                continue
            if b.marker is not None:
                if not b.marker.startswith("skip:"):
                    print(f"FAIL {b.where()}: unknown check-docs marker {b.marker!r}")
                    failures += 1
                elif b.marker.startswith("skip:") and len(b.marker) < len("skip: x"):
                    print(f"FAIL {b.where()}: a skipped block must say what runs it")
                    failures += 1
                else:
                    print(f"skip {b.where()} ({b.lang}): {b.marker}")
                    continue
            if b.lang is None:
                print(f"FAIL {b.where()}: a code block without a language")
                failures += 1
                continue
            if b.lang == "rust":
                inc = DOCTESTED.get(str(rel))
                if inc and inc[1] in (ROOT / inc[0]).read_text():
                    print(f"ok   {b.where()} (rust): a doctest of {inc[0]}")
                else:
                    print(f"FAIL {b.where()}: a rust block that no doctest runs")
                    failures += 1
                continue
            if b.lang not in SHELLS and b.lang != "python":
                print(f"FAIL {b.where()}: cannot run a {b.lang} block")
                failures += 1
                continue
            print(f"run  {b.where()} ({b.lang}) ...", flush=True)
            t0 = time.monotonic()
            code, output = run_block(b, args)
            if code == 0:
                print(f"ok   {b.where()} ({b.lang}, {time.monotonic() - t0:.1f} s)")
            else:
                print(f"FAIL {b.where()} ({b.lang}) exited with {code}:\n{b.code}\n{output}")
                failures += 1
    return failures


def self_test(args):
    """The checker fails on a failing block, an unmarked indented block and a block without a
    language, and passes a marked or good one."""
    cases = [
        ("```sh\nfalse\n```\n", 1),
        ("```python\nraise SystemExit(3)\n```\n", 1),
        ("text\n\n    indented code\n", 1),
        ("```\nno language\n```\n", 1),
        ("```rust\nfn main() {}\n```\n", 1),
        ("<!-- check-docs: skip: tested elsewhere -->\n```sh\nfalse\n```\n", 0),
        ("```sh\ntrue\n```\n```python\nprint(1)\n```\n```text\nanything\n```\n", 0),
    ]
    bad = 0
    with tempfile.TemporaryDirectory() as d:
        for i, (text, want) in enumerate(cases):
            f = Path(d) / f"case{i}.md"
            f.write_text(text)
            # The cases that must fail print FAIL lines: keep them unless the case goes wrong.
            captured = io.StringIO()
            with contextlib.redirect_stdout(captured):
                got = min(1, check([str(f)], args))
            if got != want:
                print(captured.getvalue(), end="")
                print(f"SELF-TEST FAIL: case {i} gave {got} failures, expected {want}:\n{text}")
                bad += 1
    print("self-test", "failed" if bad else f"passed ({len(cases)} cases)")
    return bad


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="*", default=DEFAULT_FILES)
    p.add_argument("--python", default=sys.executable)
    p.add_argument("--hbn", default=str(ROOT / "target" / "release" / "hbn"))
    p.add_argument("--self-test", action="store_true")
    args = p.parse_args()
    if args.self_test:
        sys.exit(1 if self_test(args) else 0)
    if not Path(args.hbn).exists():
        sys.exit(f"no hbn binary at {args.hbn}: build it (cargo build --release -p hbn-cli)")
    files = [str(ROOT / f) if not Path(f).is_absolute() else f for f in args.files]
    failures = check(files, args)
    print(f"{failures} block(s) failed" if failures else "every code block ran")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
