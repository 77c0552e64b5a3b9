"""Compact HOMER day files (householdsDifferent) into JSON: for each day file, every node's
parent before the day's first step and each later change (time, node, new parent)."""
import json, subprocess, sys, io, hashlib
from pathlib import Path
import torch

REPO = Path("/work/.mirror/Maithili+SpatioTemporalObjectTracking/repo")
OUT = Path(sys.argv[1])
COMMIT = subprocess.check_output(["git", "-C", str(REPO), "rev-parse", "HEAD"], text=True).strip()

def parents(m):
    out = []
    for row in m:
        nz = (row > 0).nonzero().flatten().tolist()
        assert len(nz) <= 1, nz
        out.append(nz[0] if nz else -1)
    return out

for h in range(5):
    base = f"data/householdsDifferent/household{h}/processed"
    tree = subprocess.check_output(["git", "-C", str(REPO), "ls-tree", "-r", "-l", "HEAD", base], text=True)
    days = []
    missing = []
    for line in tree.splitlines():
        meta, path = line.split("\t")
        mode, kind, blob, size = meta.split()
        rel = path[len(base) + 1:]
        if not (rel.startswith("train/") or rel.startswith("test/")):
            continue
        if size == "BAD" or subprocess.run(["git", "-C", str(REPO), "cat-file", "-e", blob]).returncode:
            missing.append(rel)
            continue
        raw = subprocess.check_output(["git", "-C", str(REPO), "cat-file", "blob", blob])
        steps = torch.load(io.BytesIO(raw), weights_only=True)
        start = parents(steps[0]["prev_edges"])
        cur = list(start)
        changes = []
        times = []
        for s in steps:
            times.append(int(s["time"]))
            now = parents(s["edges"])
            for i, (a, b) in enumerate(zip(cur, now)):
                if a != b:
                    changes.append([int(s["time"]), i, b])
            cur = now
        days.append({"file": rel, "git_blob": blob, "sha256": hashlib.sha256(raw).hexdigest(),
                     "first_time": times[0], "last_time": times[-1], "steps": len(times),
                     "start": start, "changes": changes})
        print(h, rel, len(changes), file=sys.stderr)
    d = OUT / f"household{h}"
    d.mkdir(parents=True, exist_ok=True)
    cd = subprocess.check_output(["git", "-C", str(REPO), "show", f"HEAD:{base}/common_data.json"])
    (d / "common_data.json").write_bytes(cd)
    (d / "days.json").write_text(json.dumps({"repository": "Maithili/SpatioTemporalObjectTracking", "commit": COMMIT,
        "path": base, "days": days, "missing_from_snapshot": missing}, separators=(",", ":")) + "\n")
