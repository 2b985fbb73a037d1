#!/usr/bin/env bash
# Hashes of the final VTK frames of a matrix of short runs, for checking that a change keeps
# every result to the last bit (the frames are written with shortest round-trip decimals, so
# equal text is equal bits).
#
#   scripts/same-bits.sh RUNNER OUTDIR
#
# RUNNER is an `rkmpm` binary (target/release/rkmpm). Run it with the runner built before the
# change and after, and compare:
#   git stash && cargo build --release --bin rkmpm && cp target/release/rkmpm /tmp/rkmpm-before
#   git stash pop && cargo build --release --bin rkmpm
#   scripts/same-bits.sh /tmp/rkmpm-before /tmp/before
#   scripts/same-bits.sh target/release/rkmpm /tmp/after
#   diff /tmp/before/sums /tmp/after/sums && echo same bits
#
# The matrix: the bundled bar with B2 APIC, B3 PIC/FLIP under MUSL, linear PIC, RK1 + VC1,
# RK2 + VC2 PIC, MLS, B2 + VC1 under MUSL; the disks as bundled (RK1 + VC1 beside B2), B2 + VC
# with contact, RK2 PIC/FLIP with slip and friction walls under gravity; the collapse,
# penetration and Taylor scenes for 2e-4 s. About 30 s on two threads.
set -euo pipefail
runner=$(realpath "$1")
out=$2
root=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$out"
mkdir -p "$out/scenes"
python3 - "$root/runner/scenes" "$out/scenes" <<'PY'
import re, sys
src, dst = sys.argv[1], sys.argv[2]
bar = open(f"{src}/bar.toml").read()
disks = open(f"{src}/disks.toml").read()
def options(scene, text):
    return re.sub(r"\[options\]\n(.*?)\n\n", "[options]\n" + text + "\n\n", scene, count=1, flags=re.S)
walls = ('[[walls]]\naxis = 1\nside = "low"\nkind = "slip"\n\n'
         '[[walls]]\naxis = 0\nside = "high"\nkind = "friction"\nfriction = 0.3\n\n[[materials]]')
runs = {
    "bar_b2_apic": options(bar, 'shape = "bspline2"\ntransfer = "apic"'),
    "bar_b3_flip_musl": options(bar, 'shape = "bspline3"\ntransfer = "pic_flip"\nflip = 0.95\nscheme = "musl"'),
    "bar_lin_pic": options(bar, 'shape = "linear"\ntransfer = "pic_flip"'),
    "bar_rk1_vc1": options(bar, 'shape = "rk"\nrk_order = 1\nrk_support = 2.0\nintegration = "vc"\nvc_order = 1\ntransfer = "apic"'),
    "bar_rk2_vc2_pic": options(bar, 'shape = "rk"\nrk_order = 2\nrk_support = 3.0\nintegration = "vc"\nvc_order = 2\ntransfer = "pic_flip"'),
    "bar_b2_mls": options(bar, 'shape = "bspline2"\ntransfer = "mls"'),
    "bar_b2_vc1_musl": options(bar, 'shape = "bspline2"\nintegration = "vc"\ntransfer = "apic"\nscheme = "musl"'),
    "disks_default": disks,
    "disks_contact_vc": options(disks, 'shape = "bspline2"\nintegration = "vc"\ntransfer = "apic"\ncontact_friction = 0.2'),
    "disks_rk2_pic_slip": options(disks, 'shape = "rk"\nrk_order = 2\nrk_support = 3.0\ntransfer = "pic_flip"\nflip = 0.5\ngravity = [0.0, -1.0]').replace("[[materials]]", walls, 1),
}
for name, scene in runs.items():
    end = 0.05 if name.startswith("bar") else 0.3
    scene = re.sub(r"end_time = [0-9.e-]+", f"end_time = {end}", scene)
    scene = re.sub(r"frames = \d+", "frames = 1", scene)
    open(f"{dst}/{name}.toml", "w").write(scene)
PY
for scene in "$out"/scenes/*.toml; do
    name=$(basename "$scene" .toml)
    "$runner" run "$scene" --out "$out/$name" --png none -q --threads 2 > "$out/$name.log"
done
for name in collapse penetration taylor; do
    "$runner" run "$name" --out "$out/$name" --end-time 2e-4 --frames 1 --png none -q --threads 2 \
        > "$out/$name.log"
done
(cd "$out" && find . -name "*.vtu" | sort | xargs md5sum) > "$out/sums"
echo "$(wc -l < "$out/sums") frames hashed in $out/sums"
