#!/usr/bin/env bash
# Pictures a newcomer gets without tuning anything, and thumbnails of the example scenes.
#
#   scripts/gallery.sh [--newcomer] [--thumbs[=NAME,...]] [OUT_DIR]
#                                                  (default: --newcomer, out/gallery)
#
# --newcomer: for every mesh of ../shared/data that hpray reads (.vtu, .msh), two scenes
#   with nothing but the data and one thing to show, and no camera (so the camera is fitted
#   to the data): an isosurface {field, value} at the middle of the field's range, and a
#   volume {color_field} with the default transfer functions. Each is rendered at 384x384
#   into OUT_DIR/newcomer/, and docs/newcomer_gallery.png puts them side by side with the
#   mesh's name under each pair.
# --thumbs: every configs/*.yaml rendered at 384x384 (configs/volume_t16_tets_1M.yaml at
#   256x256) into OUT_DIR/configs/, and shrunk to 192x192 into docs/thumbs/NAME.png (the
#   table of README.md). --thumbs=slice_nk_sinc,mfem_escher: only those configs.
# The field shown is the first of u, solution, displacement_magnitude, pressure, analytic
# that the file has. Uses build/bin/hpray (builds it if missing) and python3 with PIL
# (installs python3-pil from Debian if missing). On 2 cores --newcomer takes about 8
# minutes (the order-9 spiral and the curved order-3 volumes take a minute each).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

newcomer=0
thumbs=0
only=""
out=""
for arg in "$@"; do
  case "$arg" in
    --newcomer) newcomer=1 ;;
    --thumbs) thumbs=1 ;;
    --thumbs=*) thumbs=1; only="${arg#--thumbs=}" ;;
    -h|--help) awk 'NR > 1 && !/^#/ { exit } NR > 1 { sub(/^# ?/, ""); print }' "${BASH_SOURCE[0]}"
       exit 0 ;;
    -*) echo "gallery.sh: unknown option $arg" >&2; exit 2 ;;
    *) out="$arg" ;;
  esac
done
if [ $newcomer -eq 0 ] && [ $thumbs -eq 0 ]; then newcomer=1; fi
out="${out:-$HPRAY_ROOT/out/gallery}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
DATA="$(cd "$HPRAY_ROOT/.." && pwd)/shared/data"
HPRAY="$HPRAY_BUILD/bin/hpray"

install_packages python3-pil
[ -x "$HPRAY" ] || configure_and_build

# Renders SCENE with the given --set items, quietly; stops the script on failure.
render() {  # scene png [--set ...]
  local scene="$1" png="$2" start=$EPOCHREALTIME
  shift 2
  "$HPRAY" render "$scene" -q --set "output.png=$png" --set output.exr=null \
    --set output.stats=null --set output.hits=null --set output.rgba=null "$@"
  printf '    %s: %.1f s\n' "${png#"$out"/}" "$(awk "BEGIN { print $EPOCHREALTIME - $start }")"
}

if [ $newcomer -eq 1 ]; then
  [ -d "$DATA" ] || { echo "gallery.sh: no shared data at $DATA" >&2; exit 2; }
  dir="$out/newcomer"
  mkdir -p "$dir"
  list="$dir/list.tsv"
  : > "$list"
  for mesh in "$DATA"/*.vtu "$DATA"/*.msh; do
    name="$(basename "${mesh%.*}")"
    field=""
    step "newcomer scenes of $name"
    # The field to show and the middle of its range, from hpray info.
    read -r field mid < <("$HPRAY" info "$mesh" --json 2>/dev/null | /usr/bin/python3 -c '
import json, sys
fields = json.load(sys.stdin)["fields"]
for f in ["u", "solution", "displacement_magnitude", "pressure", "analytic"]:
    if f in fields and fields[f]["components"] == 1:
        lo, hi = fields[f]["range"]
        print(f, repr(0.5 * (lo + hi)))
        break
') || true
    if [ -z "${field:-}" ]; then
      echo "    no scalar field among u, solution, displacement_magnitude, pressure, analytic: skipped"
      continue
    fi
    printf 'data: {mesh: "%s"}\nisosurfaces: [{field: %s, value: %s}]\n' \
      "$mesh" "$field" "$mid" > "$dir/$name.iso.yaml"
    printf 'data: {mesh: "%s"}\nvolume: {color_field: %s}\n' "$mesh" "$field" \
      > "$dir/$name.volume.yaml"
    for kind in iso volume; do
      render "$dir/$name.$kind.yaml" "$dir/$name.$kind.png" \
        --set camera.width=384 --set camera.height=384
    done
    printf '%s\t%s\t%s\n' "$name" "$field" "$mid" >> "$list"
  done
  step "contact sheet docs/newcomer_gallery.png"
  /usr/bin/python3 - "$dir" "$HPRAY_ROOT/docs/newcomer_gallery.png" <<'EOF'
import os, sys
from PIL import Image, ImageDraw, ImageFont
src, dst = sys.argv[1], sys.argv[2]
rows = [line.rstrip("\n").split("\t") for line in open(os.path.join(src, "list.tsv"))]
S, PAD, TEXT, COLS = 192, 8, 50, 4  # picture size, gap, caption height, pairs per row
try:
    font = ImageFont.truetype("DejaVuSans.ttf", 13)
except OSError:
    font = ImageFont.load_default()
cell_w, cell_h = 2 * S + PAD, S + TEXT
n_rows = (len(rows) + COLS - 1) // COLS
sheet = Image.new("RGB", (COLS * (cell_w + 2 * PAD) + PAD, n_rows * (cell_h + PAD) + PAD),
                  (235, 235, 235))
draw = ImageDraw.Draw(sheet)
for k, (name, field, mid) in enumerate(rows):
    x0 = PAD + (k % COLS) * (cell_w + 2 * PAD)
    y0 = PAD + (k // COLS) * (cell_h + PAD)
    for j, kind in enumerate(["iso", "volume"]):
        im = Image.open(os.path.join(src, f"{name}.{kind}.png")).convert("RGB")
        sheet.paste(im.resize((S, S), Image.LANCZOS), (x0 + j * (S + PAD), y0))
    draw.text((x0, y0 + S + 2), name, fill=(0, 0, 0), font=font)
    draw.text((x0, y0 + S + 17), f"left: isosurface {field} = {float(mid):.4g}",
              fill=(70, 70, 70), font=font)
    draw.text((x0, y0 + S + 32), f"right: volume of {field}", fill=(70, 70, 70), font=font)
sheet.save(dst, optimize=True)
print(f"{dst}: {sheet.size[0]}x{sheet.size[1]}, {os.path.getsize(dst)} bytes")
EOF
fi

if [ $thumbs -eq 1 ]; then
  dir="$out/configs"
  mkdir -p "$dir" "$HPRAY_ROOT/docs/thumbs"
  names=()
  if [ -n "$only" ]; then
    IFS=, read -r -a names <<< "$only"
  else
    for scene in "$HPRAY_ROOT"/configs/*.yaml; do names+=("$(basename "${scene%.yaml}")"); done
  fi
  for name in "${names[@]}"; do
    scene="$HPRAY_ROOT/configs/$name.yaml"
    [ -f "$scene" ] || { echo "gallery.sh: no configs/$name.yaml" >&2; exit 2; }
    size=384
    case "$name" in *_1M) size=256 ;; esac
    step "configs/$name.yaml at ${size}x${size}"
    render "$scene" "$dir/$name.png" --set "camera.width=$size" --set "camera.height=$size"
  done
  step "thumbnails in docs/thumbs/"
  /usr/bin/python3 - "$dir" "$HPRAY_ROOT/docs/thumbs" "${names[@]}" <<'EOF'
import os, sys
from PIL import Image
src, dst, names = sys.argv[1], sys.argv[2], sys.argv[3:]
total = 0
for name in names:
    png = os.path.join(src, name + ".png")
    out = os.path.join(dst, os.path.basename(png))
    Image.open(png).convert("RGB").resize((192, 192), Image.LANCZOS).save(out, optimize=True)
    total += os.path.getsize(out)
print(f"{dst}: {total} bytes")
EOF
fi
step "done: pictures in $out"
