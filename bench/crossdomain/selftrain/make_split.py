#!/usr/bin/env python3
"""The fixed self-training split of a cross-domain set (issue 38, part 3).

The first half of the image ids (Blender set: ids 1-60, xd_00000.jpg ... xd_00059.jpg;
Mitsuba set: ids 1-50) is the unlabeled-train half: links to them go into unlabeled/
(their labels are never read). The second half is the test half: its images and
annotations go into test.json, a COCO file that test.toml scores. Both sets draw each
image independently per id (make_crossdomain.py and make_crossdomain2.py seed image k
with [seed, k]), so a split by id is a random split. Standard library only; run from the
repository root:

    python3 bench/crossdomain/selftrain/make_split.py            # the Blender set
    python3 bench/crossdomain/selftrain/make_split.py \
        bench/crossdomain2/set bench/crossdomain2/selftrain   # the Mitsuba set
"""
import json
import os
import sys

SET, OUT = (sys.argv[1], sys.argv[2]) if len(sys.argv) == 3 else (
    "bench/crossdomain/set", "bench/crossdomain/selftrain")


def main():
    with open(os.path.join(SET, "annotations.json")) as f:
        coco = json.load(f)
    images = sorted(coco["images"], key=lambda i: i["id"])
    n = len(images)
    assert n % 2 == 0 and [i["id"] for i in images] == list(range(1, n + 1))
    SPLIT_ID = n // 2  # ids <= n/2: unlabeled-train, ids > n/2: test
    unl = os.path.join(OUT, "unlabeled")
    os.makedirs(unl, exist_ok=True)
    for name in os.listdir(unl):
        os.remove(os.path.join(unl, name))
    for im in images:
        if im["id"] <= SPLIT_ID:
            name = os.path.basename(im["file_name"])
            os.symlink(os.path.relpath(os.path.join(SET, "images", name), unl), os.path.join(unl, name))
    test_ids = {i["id"] for i in images if i["id"] > SPLIT_ID}
    test = dict(coco)
    test["images"] = [i for i in images if i["id"] in test_ids]
    test["annotations"] = [a for a in coco["annotations"] if a["image_id"] in test_ids]
    tmp = os.path.join(OUT, "test.json.tmp")
    with open(tmp, "w") as f:
        json.dump(test, f)
    os.replace(tmp, os.path.join(OUT, "test.json"))
    print(f"{SPLIT_ID} unlabeled links, {len(test['images'])} test images, "
          f"{len(test['annotations'])} test instances")


if __name__ == "__main__":
    main()
