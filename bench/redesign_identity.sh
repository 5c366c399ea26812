#!/usr/bin/env bash
# Behaviour identity of a refactor (issue 40, the method of issue 13): run one binary
# through `--smoke` training of each model family, renders, every export format,
# `eval`, `predict` (checkpoint and ONNX) and `coco-eval`, then compare two such
# recordings file by file.
#
#   bench/redesign_identity.sh record  BIN DIR    # run everything, outputs under DIR
#   bench/redesign_identity.sh compare DIR_A DIR_B
#
# `record` runs in DIR (its own render cache, DIR/runs/cache), one thread
# (RAYON_NUM_THREADS=1), and stores each command's stdout as DIR/stdout/<step>.txt.
# `compare` demands every file byte-identical (`cmp`) except:
#   - JSON / JSONL files: compared after deleting wall-clock keys (`time`, `train_time`,
#     `data_wait_s`, `images_per_s` and every key ending in `_s`, at any depth);
#   - JSON keys `val_time` (the validation's time split) are deleted too;
#   - CSV files: compared without columns whose header contains `time` or ends in `_s`;
#   - checkpoints (`*.bpk`): Burn's records carry a random per-process `param_id` for each
#     parameter, so those 8-byte ids are masked, and the `optim` section (optimiser state
#     keyed by the same ids, in their order) is cut off; header and weights are compared;
#   - `*.log` files and the stdout of `train` (they print wall-clock times) are not
#     compared; the stdout of `eval --json` and `coco-eval --json` is.
# It prints one line per differing file and exits 1 if any differ.
# `DEVICE=ndarray bench/redesign_identity.sh record …` trains, evaluates and predicts on
# ndarray instead of flex (the default), for refactors that land beside a change of flex's
# arithmetic; ONNX export's reference outputs are still computed on flex.
set -euo pipefail

die() { echo "redesign_identity: $*" >&2; exit 2; }

record() {
    local bin dir device
    # DEVICE=ndarray records through Burn's ndarray backend: a change of flex's own
    # arithmetic (issue 37's convolution engine) then leaves the comparison meaningful.
    device=${DEVICE:-flex}
    bin=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
    dir=$2
    [ -x "$bin" ] || die "not an executable: $1"
    mkdir -p "$dir/stdout"
    cd "$dir"
    export RAYON_NUM_THREADS=1
    local fam cfg
    # quickstart has no C2PSA block, which ultralytics' key layout needs, so the
    # safetensors export of YOLO uses yolo_syn250.toml (C2PSA on).
    for fam in yolo:quickstart.toml yolo_c2psa:yolo_syn250.toml \
        maskrcnn:maskrcnn_r50_syn250.toml mask2former:mask2former_syn250.toml; do
        cfg=${fam#*:}
        fam=${fam%%:*}
        echo "== train $fam ($cfg --smoke)"
        "$bin" train --config "$cfg" --smoke --run-dir "runs/$fam" --device "$device" \
            >"stdout/train_$fam.log" 2>&1
        echo "== eval $fam"
        "$bin" eval --checkpoint "runs/$fam/best.bpk" --split test --json --device "$device" \
            >"stdout/eval_$fam.txt"
    done
    echo "== export"
    for fam in yolo_c2psa maskrcnn; do
        "$bin" export --checkpoint "runs/$fam/best.bpk" --format safetensors \
            --out "export/$fam.safetensors" >"stdout/export_st_$fam.txt"
    done
    for fam in yolo yolo_c2psa maskrcnn; do
        "$bin" export --checkpoint "runs/$fam/best.bpk" --format onnx \
            --out "export/$fam.onnx" --reference >"stdout/export_onnx_$fam.txt"
    done
    # Mask2Former exports neither format: the refusal (message, exit status) is compared.
    for fmt in safetensors onnx; do
        rc=0
        "$bin" export --checkpoint runs/mask2former/best.bpk --format $fmt \
            --out "export/mask2former.$fmt" >"stdout/export_${fmt}_mask2former.txt" 2>&1 || rc=$?
        echo "exit $rc" >>"stdout/export_${fmt}_mask2former.txt"
    done
    echo "== render"
    "$bin" render --out render/synthetic --count 3 --size 96 --randomize all \
        >"stdout/render_synthetic.txt"
    "$bin" render --out render/proxy --count 2 --size 96 --preset proxy-real \
        >"stdout/render_proxy.txt"
    echo "== predict"
    "$bin" predict --checkpoint runs/yolo/best.bpk --input render/proxy/images --device "$device" \
        --out predict/yolo >"stdout/predict_yolo.txt"
    "$bin" predict --checkpoint runs/maskrcnn/best.bpk --input render/proxy/images --device "$device" \
        --out predict/maskrcnn --augment >"stdout/predict_maskrcnn_tta.txt"
    "$bin" predict --onnx export/yolo.onnx --input render/proxy/images \
        --out predict/yolo_onnx --threads 1 >"stdout/predict_yolo_onnx.txt"
    echo "== coco-eval"
    "$bin" coco-eval --gt render/proxy/annotations.json \
        --dt predict/yolo/results.json --iou-type segm --json >"stdout/coco_eval.txt"
    echo "recorded under $dir"
}

normalise_json() {
    jq -S -c 'walk(if type == "object" then with_entries(select(.key
        | test("^(time|train_time|val_time|data_wait_s|images_per_s)$|_s$") | not)) else . end)' "$1"
}

normalise_bpk() {
    perl -0777 -pe 's/hparam_id\x1b.{8}/hparam_id\x1bXXXXXXXX/gs; s/\x05\x00{7}optim.*//s' "$1"
}

normalise_csv() {
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) keep[i] = ($i !~ /time|_s$/) }
        { out = ""; for (i = 1; i <= NF; i++) if (keep[i]) out = out (out == "" ? "" : ",") $i;
          print out }' "$1"
}

compare() {
    local a=$1 b=$2 bad=0 n=0 f
    [ -d "$a" ] && [ -d "$b" ] || die "compare needs two recorded folders"
    while IFS= read -r f; do
        case "$f" in
        */cache/* | *.log) continue ;;
        esac
        n=$((n + 1))
        if [ ! -f "$b/$f" ]; then
            echo "missing in $b: $f"; bad=1; continue
        fi
        case "$f" in
        *.json | *.jsonl)
            if [[ "$f" == *.jsonl ]]; then
                diff -q <(jq -c . "$a/$f" | while read -r l; do normalise_json <(echo "$l"); done) \
                    <(jq -c . "$b/$f" | while read -r l; do normalise_json <(echo "$l"); done) \
                    >/dev/null || { echo "differs (timing keys masked): $f"; bad=1; }
            else
                diff -q <(normalise_json "$a/$f") <(normalise_json "$b/$f") >/dev/null ||
                    { echo "differs (timing keys masked): $f"; bad=1; }
            fi ;;
        *.bpk)
            cmp -s <(normalise_bpk "$a/$f") <(normalise_bpk "$b/$f") ||
                { echo "differs (parameter ids masked, optimiser state cut): $f"; bad=1; } ;;
        *.csv)
            diff -q <(normalise_csv "$a/$f") <(normalise_csv "$b/$f") >/dev/null ||
                { echo "differs (time columns dropped): $f"; bad=1; } ;;
        *)
            cmp -s "$a/$f" "$b/$f" || { echo "differs: $f"; bad=1; } ;;
        esac
    done < <(cd "$a" && find . -type f | sed 's|^\./||' | sort)
    while IFS= read -r f; do
        [ -f "$a/$f" ] || { echo "only in $b: $f"; bad=1; }
    done < <(cd "$b" && find . -type f ! -path '*/cache/*' ! -name '*.log' | sed 's|^\./||' | sort)
    echo "$n files compared: $([ $bad = 0 ] && echo identical || echo DIFFERENT)"
    return $bad
}

case "${1:-}" in
record) [ $# = 3 ] || die "usage: $0 record BIN DIR"; record "$2" "$3" ;;
compare) [ $# = 3 ] || die "usage: $0 compare DIR_A DIR_B"; compare "$2" "$3" ;;
*) die "usage: $0 record BIN DIR | compare DIR_A DIR_B" ;;
esac
