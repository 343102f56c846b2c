"""Checks that the AVX2 code of a built binary holds no legacy-SSE instruction.

usage: python3 scripts/check_avx2_encoding.py BINARY

`hbn_core::simd::vectorised` runs the estimator's hot loops in a function compiled for AVX2
(`hbn_core::simd::run_avx2`). An instruction in the old SSE encoding inside it (a library's
inline assembly: `libm::sqrt` is `sqrtsd`) mixes the two encodings, which on some CPUs stalls
every such instruction: on an AMD EPYC machine it makes the exact GP's EKF step several times
slower and the UKF step about 9x slower. The compiler cannot re-encode inline
assembly, so this reads the machine code: every instruction of every `run_avx2` copy, and of
the AVX2 kernels written with intrinsics (`lower_packed_times_avx2`), that names an xmm or ymm
register must be VEX-encoded (its mnemonic starts with `v`).

Exits 1 when one is not, or when one of those functions is not found (so the check cannot pass
vacuously); exits 0 with a notice when objdump is not installed.
"""
import re
import shutil
import subprocess
import sys

# The functions compiled for AVX2: `vectorised`'s wrapper and the intrinsics kernels.
AVX2_FUNCTIONS = (
    "hbn_core::simd::run_avx2",
    "hbn_core::simd::lower_packed_times_avx2",
)


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    if shutil.which("objdump") is None:
        print("notice: objdump is not installed: the AVX2 encoding check is skipped")
        return 0
    out = subprocess.run(
        ["objdump", "-d", "-C", "--no-show-raw-insn", sys.argv[1]],
        check=True, capture_output=True, text=True,
    ).stdout
    inside = False
    found = {name: 0 for name in AVX2_FUNCTIONS}
    instructions = 0
    legacy = {}
    for line in out.splitlines():
        if line.endswith(">:"):
            names = [name for name in AVX2_FUNCTIONS if name in line]
            inside = bool(names)
            for name in names:
                found[name] += 1
            continue
        if not inside:
            continue
        m = re.match(r"\s*[0-9a-f]+:\s+(\S+)\s*(.*)", line)
        if not m:
            continue
        instructions += 1
        mnemonic, operands = m.groups()
        if re.search(r"%[xy]mm", operands) and not mnemonic.startswith("v"):
            legacy[mnemonic] = legacy.get(mnemonic, 0) + 1
    missing = [name for name, count in found.items() if count == 0]
    if missing:
        print(f"error: no {', '.join(missing)} in {sys.argv[1]}", file=sys.stderr)
        return 1
    functions = sum(found.values())
    if legacy:
        print(
            f"error: {sum(legacy.values())} legacy-SSE instructions in the AVX2 code of "
            f"{sys.argv[1]} (AVX2 functions: {found}): {legacy}. A function inlined "
            "into hbn_core::simd::vectorised or an AVX2 kernel uses inline assembly "
            "(libm::sqrt, say); use hbn_core::simd::sqrt or a core operation instead.",
            file=sys.stderr,
        )
        return 1
    print(f"AVX2 functions: {found}, instructions: {instructions}, all VEX-encoded")
    return 0


if __name__ == "__main__":
    sys.exit(main())
