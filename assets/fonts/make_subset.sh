#!/bin/sh
# Rebuilds DejaVuSans-subset.ttf (the only font chicktrain's plots use, embedded in the
# binary so no system fonts are needed): DejaVu Sans 2.37 (Debian fonts-dejavu-core)
# cut to printable ASCII plus ± · × µ – — − ≤ ≥, without hinting (10.7 KB instead of 760 KB).
# Needs fonttools (pip install fonttools).
set -e
pyftsubset /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf \
  --unicodes="U+0020-007E,U+00B1,U+00B7,U+00D7,U+2013,U+2014,U+2212,U+2264,U+2265,U+00B5" \
  --layout-features='' --no-hinting --output-file=DejaVuSans-subset.ttf
