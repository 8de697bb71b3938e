#!/usr/bin/env bash
# Where a lavapipe render spends its time inside the JIT-compiled integrator. perf sees llvmpipe's
# shader code only as anonymous memory, and Mesa's own disassembly (GALLIVM_DEBUG=asm) stops at
# the first instruction its disassembler cannot decode, so this samples a running render with
# perf, copies the executable anonymous mappings out of /proc/PID/mem while the render still runs,
# disassembles them with objdump and attributes the samples to instructions.
#
# Usage (as root, perf installed): bench/jit_profile.sh OUT_DIR [SECONDS]
#   LIGHTFARM_BIN=$(scripts/lavapipe-trixie.sh bin) bench/jit_profile.sh /tmp/prof   (Mesa 26)
# Renders the head of bench/compare.sh at 256², 8192 spp (long enough to outlast the sampling),
# samples it for SECONDS (default 10) after 7 s of warm-up, then stops it. Writes under OUT_DIR:
#   summary.txt   shares: JIT code, each executable mapping, instructions with a stack operand
#                 (spills), gathers, and the hottest 8 KB windows of the largest mapping
#   hot.txt       every instruction of the largest mapping with its sample count
#   jit_*.bin     the code as copied, jit.asm its disassembly
# The function starts at the mapping's first byte; the image-read helpers sit in a mapping of
# their own (llvmpipe calls them indirectly, one call per textureLoad of a storage image).
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 1 ] || { sed -n 2,17p "$0" >&2; exit 2; }
out=$1 secs=${2:-10}
command -v perf > /dev/null || { echo "jit_profile: perf is not installed (apt-get install linux-perf)" >&2; exit 1; }
command -v objdump > /dev/null || { echo "jit_profile: objdump is not installed (apt-get install binutils)" >&2; exit 1; }
mkdir -p "$out"
if [ -z "${LIGHTFARM_BIN:-}" ]; then
    source scripts/setup-system.sh
    cargo build --locked -q -p lightfarm >&2
    LIGHTFARM_BIN="$CARGO_TARGET_DIR/debug/lightfarm"
fi
"$LIGHTFARM_BIN" render --scene assets/heads/LeePerrySmith_textured.glb \
    --hdri assets/hdri/studio_small_03_1k.hdr --size 256x256 --spp 8192 --max-depth 8 \
    --out "$out/render.exr" > "$out/render.log" 2>&1 &
launcher=$!
pid=""
trap '[ -n "$pid" ] && kill "$pid" 2> /dev/null; wait 2> /dev/null || true' EXIT
# The render's own process, below the launcher (LIGHTFARM_BIN may be a wrapper that chroots).
find_render() {
    local p=$1 c
    [ "$(cat /proc/"$p"/comm 2> /dev/null)" = lightfarm ] && { echo "$p"; return 0; }
    for c in $(pgrep -P "$p"); do find_render "$c" && return 0; done
    return 1
}
sleep 7
pid=$(find_render "$launcher") || { echo "jit_profile: no lightfarm process (see $out/render.log)" >&2; exit 1; }
perf record -q -F 1999 -p "$pid" -o "$out/perf.data" -- sleep "$secs" > /dev/null 2>&1
kill -0 "$launcher" 2> /dev/null || { echo "jit_profile: the render ended before the copy; see $out/render.log" >&2; exit 1; }
perf script -i "$out/perf.data" -F ip,dso 2> /dev/null > "$out/ips.txt"
python3 - "$pid" "$out" <<'PY'
import bisect, collections, os, re, subprocess, sys
pid, out = int(sys.argv[1]), sys.argv[2]
samples = collections.Counter()
total = 0
for line in open(f"{out}/ips.txt"):
    parts = line.split()
    if not parts:
        continue
    total += 1
    if "perf-" in line:  # anonymous (JIT) code
        samples[int(parts[0], 16)] += 1
maps = []
with open(f"/proc/{pid}/maps") as f, open(f"/proc/{pid}/mem", "rb") as mem:
    for line in f:
        fields = line.split()
        if "x" not in fields[1] or len(fields) > 5:
            continue  # executable anonymous mappings only
        a, b = (int(x, 16) for x in fields[0].split("-"))
        mem.seek(a)
        data = mem.read(b - a)
        open(f"{out}/jit_{a:x}.bin", "wb").write(data)
        maps.append((a, b))
per_map = {m: sum(c for ip, c in samples.items() if m[0] <= ip < m[1]) for m in maps}
lines = [f"samples: {total}, in JIT code: {sum(samples.values())} ({100 * sum(samples.values()) / max(total, 1):.1f}%)"]
quiet = 0
for (a, b), c in sorted(per_map.items(), key=lambda x: -x[1]):
    if c * 1000 < total:
        quiet += 1
        continue
    lines.append(f"  mapping {a:x}-{b:x} ({(b - a) // 1024} KB): {c} ({100 * c / max(total, 1):.1f}%)")
lines.append(f"  ({quiet} more executable anonymous mappings under 0.1% each)")
big = max(maps, key=lambda m: per_map[m])
asm = subprocess.run(["objdump", "-D", "-b", "binary", "-m", "i386:x86-64", f"--adjust-vma={big[0]:#x}",
                      f"{out}/jit_{big[0]:x}.bin"], capture_output=True, text=True, check=True).stdout
open(f"{out}/jit.asm", "w").write(asm)
ins = []
for l in asm.splitlines():
    m = re.match(r"\s*([0-9a-f]+):\t[0-9a-f ]+\t(.*)", l)
    if m:
        ins.append((int(m.group(1), 16), m.group(2).strip()))
addrs = [a for a, _ in ins]
cnt = collections.Counter()
for ip, c in samples.items():
    if big[0] <= ip < big[1]:
        cnt[bisect.bisect_right(addrs, ip) - 1] += c
in_big = sum(cnt.values()) or 1
stack = sum(c for i, c in cnt.items() if "(%rsp)" in ins[i][1])
# A gather's latency lands on the instruction after it.
gather = sum(c for i, c in cnt.items() if "gather" in ins[i][1] or (i > 0 and "gather" in ins[i - 1][1]))
lines.append(f"largest mapping: {len(ins)} instructions, {sum(1 for _, t in ins if 'gather' in t)} gathers, "
             f"{sum(1 for _, t in ins if t.startswith('call'))} calls")
lines.append(f"  samples on instructions with a stack operand (spills, reloads): {100 * stack / in_big:.1f}%")
lines.append(f"  samples on gathers and the instruction after each: {100 * gather / in_big:.1f}%")
windows = collections.Counter()
for i, c in cnt.items():
    windows[(ins[i][0] - big[0]) // 0x2000] += c
lines.append("  hottest 8 KB windows (offset: share of all samples; calls in the window):")
for w, c in windows.most_common(8):
    calls = sum(1 for a, t in ins if t.startswith("call") and (a - big[0]) // 0x2000 == w)
    lines.append(f"    {w * 0x2000:#7x}: {100 * c / max(total, 1):.1f}% ({calls} calls)")
open(f"{out}/summary.txt", "w").write("\n".join(lines) + "\n")
with open(f"{out}/hot.txt", "w") as f:
    for i, (a, t) in enumerate(ins):
        f.write(f"{cnt.get(i, 0):6d} {a - big[0]:7x} {t}\n")
print("\n".join(lines))
PY
