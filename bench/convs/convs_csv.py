"""Reading the `convs.csv` of `chicktrain bench convs`, shared by binaries_pair.py and
ort_convs.py (no dependency beyond the standard library)."""


def used_ms(r):
    """What flex's conv2d runs for this row: the engine, except forwards that dispatch keeps
    on the old path (`engine_forward` false: 1×1 stride 1, depthwise). The same rule as
    `ConvTiming::used_ms` in src/bench/convs.rs."""
    if r["pass"] == "forward" and r["engine_forward"] != "true":
        return float(r["old_ms"])
    return float(r["new_ms"])
