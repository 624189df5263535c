"""One line per `atmo-sim explain` output folder named on stdin (under the
folder given as the argument): the effects claimed, those selected but
refused, the 0.5 s velocity error before -> after, and the scalar
parameters of the claimed effects (n.i.: not identified)."""

import json
import sys
from pathlib import Path


def norm(m):
    return sum(x * x for x in m["velocity"]) ** 0.5 if m["starts"] else float("nan")


def main():
    root = Path(sys.argv[1])
    for name in (line.strip() for line in sys.stdin if line.strip()):
        d = json.loads((root / name / "explain.json").read_text())
        claimed = [e for e in d["effects"] if e["selected"]]
        refused = [e["name"] for e in d["effects"]
                   if not e["selected"] and e["selection_frequency"] >= 0.5]
        before, after = norm(d["multistep_before"]), norm(d["multistep_after"])
        params = [
            f"{p['name']}={p['value']:.4g}{'' if p['identified'] else ' (n.i.)'}"
            for e in claimed if e["name"] != "ground_effect"
            for p in e["parameters"]
        ]
        print(f"{name:34s} claimed {[e['name'] for e in claimed]} "
              f"refused {refused} 0.5 s {before:.3f} -> {after:.3f} m/s  "
              + " ".join(params))


if __name__ == "__main__":
    main()
