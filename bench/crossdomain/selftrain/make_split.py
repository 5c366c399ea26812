#!/usr/bin/env python3
"""The fixed self-training split of the Blender cross-domain set (issue 38, part 3).

Image ids 1-60 (xd_00000.jpg ... xd_00059.jpg) are the unlabeled-train half: links to
them go into unlabeled/ (their labels are never read). Ids 61-120 are the test half:
their images and annotations go into test.json, a COCO file that test.toml scores.
The images were drawn independently per id (make_crossdomain.py seeds image k with
[seed, k]), so a split by id is a random split. Standard library only; run from the
repository root:

    python3 bench/crossdomain/selftrain/make_split.py
"""
import json
import os

SET = "bench/crossdomain/set"
OUT = "bench/crossdomain/selftrain"
SPLIT_ID = 60  # ids <= 60: unlabeled-train, ids > 60: test


def main():
    with open(os.path.join(SET, "annotations.json")) as f:
        coco = json.load(f)
    images = sorted(coco["images"], key=lambda i: i["id"])
    assert len(images) == 120 and [i["id"] for i in images] == list(range(1, 121))
    unl = os.path.join(OUT, "unlabeled")
    os.makedirs(unl, exist_ok=True)
    for name in os.listdir(unl):
        os.remove(os.path.join(unl, name))
    for im in images:
        if im["id"] <= SPLIT_ID:
            name = os.path.basename(im["file_name"])
            os.symlink(os.path.join("..", "..", "set", "images", name), os.path.join(unl, name))
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
