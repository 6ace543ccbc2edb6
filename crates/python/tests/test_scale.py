"""The Dask recipe of docs/scale.md on a small local cluster (skipped without dask)."""

import shutil

import pytest

import dhct


def correct_one(path):
    """docs/scale.md's function: one row per file, the model parameters or the error."""
    try:
        result = dhct.correct(path, lattice="graphite")
    except dhct.DhctError as error:
        return {"input": path, "status": "failed", "error": str(error)}
    row = {"input": path, "status": "ok", "warnings": [w["code"] for w in result.warnings]}
    row["lattice_constant_m"] = result.lattice["regions"][0]["lattice_constant_m"][0]
    for name, p in result.parameters.items():
        row[name] = p["value"]
        row[name + "_sigma"] = p["sigma"]
    return row


def test_dask_bag_over_files_on_a_local_cluster(example, result, tmp_path):
    db = pytest.importorskip("dask.bag")
    distributed = pytest.importorskip("dask.distributed")
    files = []
    for i in range(4):
        path = tmp_path / f"scan{i}.sm4"
        shutil.copy(example, path)
        files.append(str(path))
    broken = tmp_path / "broken.sm4"
    broken.write_bytes(example.read_bytes()[:5000])
    files.append(str(broken))
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster):
        rows = db.from_sequence(files, npartitions=len(files)).map(correct_one).compute()
    assert [r["status"] for r in rows] == ["ok"] * 4 + ["failed"]
    assert "truncated" in rows[-1]["error"]
    expected = result.parameters
    for row in rows[:4]:
        for name, p in expected.items():
            assert row[name] == pytest.approx(p["value"], rel=1e-9), name
