"""Open a .rrd recording written by `tnd ... --rerun FILE.rrd` with the rerun SDK's own CLI (the `rerun` binary of the
pinned rerun-sdk wheel, the same version as the Rust SDK tnd links): `rerun rrd verify` must load and interpret it,
and `rerun rrd print` must list every expected entity with the expected archetype column and at least N rows.

    python rrd_check.py FILE.rrd ENTITY=Archetype:component[>=ROWS] ...
"""

import os
import re
import subprocess
import sys


def main() -> None:
    path, *expected = sys.argv[1:]
    rerun = os.path.join(os.path.dirname(sys.executable), "rerun")
    env = dict(os.environ, RERUN_ANALYTICS="false")
    subprocess.run([rerun, "rrd", "verify", path], check=True, env=env, capture_output=True)
    out = subprocess.run(
        [rerun, "rrd", "print", path], check=True, env=env, capture_output=True, text=True
    ).stdout
    rows: dict[tuple[str, str], int] = {}
    for m in re.finditer(r"with (\d+) rows .*? - (\S+) - data columns: \[([^\]]*)\]", out):
        n, entity, columns = int(m.group(1)), m.group(2), m.group(3).split()
        for c in columns:
            rows[(entity, c)] = rows.get((entity, c), 0) + n
    if not rows:
        sys.exit(f"{path}: rerun rrd print listed no chunks:\n{out[-2000:]}")
    for spec in expected:
        want, _, least = spec.partition(">=")
        entity, _, column = want.partition("=")
        n = rows.get((entity, column), 0)
        if n < int(least or 1):
            have = sorted(f"{e}={c}" for e, c in rows)
            sys.exit(f"{path}: {entity} has {n} rows of {column}, expected >= {least or 1}; it has: {have}")
    print(f"{path}: rerun verified it; {len(rows)} entity columns, all {len(expected)} expected present")


if __name__ == "__main__":
    main()
