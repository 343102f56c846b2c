"""Runs every ```python block of README.md and hbn-py/README.md (from the repository root),
so a snippet that a user copies works. The Rust blocks of README.md run as doctests of the
root crate (`cargo test`). Usage: python scripts/check_docs.py (with the hbn wheel installed).
"""
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ["README.md", "hbn-py/README.md"]


def blocks(path):
    text = (ROOT / path).read_text()
    for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M):
        line = text[: m.start()].count("\n") + 1
        yield line, m.group(1)


def main():
    failed = 0
    ran = 0
    for doc in DOCS:
        for line, code in blocks(doc):
            ran += 1
            r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                               text=True, timeout=600)
            status = "ok" if r.returncode == 0 else "FAILED"
            print(f"{doc}:{line}: python block {status}")
            if r.returncode != 0:
                failed += 1
                print(r.stdout + r.stderr)
    print(f"{ran} python blocks, {failed} failed")
    if ran == 0 or failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
