"""``demos/patch_test.py`` on the committed gmsh meshes (``meshes/``): the methods that pass the
linear patch test to round-off do so on the unstructured mesh, the others are reported with
their measured error, and the demo's self-check fails when a method expected to pass does not.
"""

from __future__ import annotations

import json
import pathlib

import dolfinx_meshfree as mf

import pytest
from conftest import load_demo
from mpi4py import MPI

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: Cells of the committed irregular meshes (meshes/make_meshes.py --cells 6).
GMSH_CELLS = {"quadrilateral": 55, "triangle": 106}


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_exact_methods_on_the_gmsh_mesh(cell, shared_dir):
    """FE, and EFG and the Lagrange coupling with consistent integration: 1e-10 (measured
    1e-15 to 3e-14) on the unstructured mesh, serial and on 2 ranks."""
    comm = MPI.COMM_WORLD
    demo = load_demo("patch_test")
    out = shared_dir / "p.json"
    for method in ("fe", "efg", "lagrange"):
        rec = demo.main(["--method", method, "--mesh", "irregular", "--cell", cell,
                         "--consistent", "--json", str(out)])  # fmt: skip
        assert rec["cells"] == GMSH_CELLS[cell]
        assert rec["target"] == 1e-10
        assert rec["max_error"] <= 1e-10
        assert rec["status"] == "PASS"
        assert rec["ranks"] == comm.size
    comm.Barrier()
    data = json.loads(out.read_text())
    assert data["method"] == "lagrange" and data["mesh"] == "irregular" and data["consistent"]
    assert data["max_error"] <= 1e-10


def test_ramp_exact_with_vci_and_reported_with_gauss():
    """Both ramps with consistent integration (VCI over the patch and the interface cells): exact
    on the gmsh quadrilaterals (measured 2.1e-13 and 1.9e-13; bound 1e-10) and judged (PASS, in
    the demo's expected set). With the paper's 4 x 4 Gauss rule the ramp misses 1e-6 on the gmsh
    triangles (measured 1.15e-4; bounds 5e-5 to 2.5e-4): reported as MISSED with the figure and
    a note naming both remedies, and the demo still succeeds."""
    demo = load_demo("patch_test")
    for method in ("ramp", "ramp-cubic"):
        rec = demo.main(["--method", method, "--mesh", "irregular", "--consistent"])
        assert rec["consistent"] and rec["expected_to_pass"] and rec["target"] == 1e-10
        assert rec["max_error"] <= 1e-10
        assert rec["status"] == "PASS"
    rec = demo.main(["--method", "ramp", "--mesh", "irregular", "--cell", "triangle"])
    assert rec["consistent"] is False and not rec["expected_to_pass"]
    assert rec["target"] == 1e-6
    assert 5e-5 <= rec["max_error"] <= 2.5e-4
    assert rec["status"] == "MISSED"
    assert "--consistent" in rec["note"] and "dense-gauss" in rec["note"]


def test_all_methods_table_and_self_check(shared_dir):
    """``--method all``: one record per method, the expected ones pass; a method wrongly
    expected to pass (bridging with Gauss quadrature, 3.5e-2) makes the demo exit with 1."""
    comm = MPI.COMM_WORLD
    demo = load_demo("patch_test")
    out = shared_dir / "all.json"
    records = demo.main(["--method", "all", "--mesh", "irregular", "--consistent",
                         "--json", str(out)])  # fmt: skip
    assert [r["method"] for r in records] == ["fe", "efg", *mf.COUPLINGS]
    status = {r["method"]: r["status"] for r in records}
    # with VCI every method but bridging and master-slave is exact on the gmsh quadrilaterals
    # (measured 8.9e-16 to 9.7e-13; bound 1e-10)
    exact = ("fe", "efg", "lagrange", "edge-to-edge", "ramp", "ramp-cubic")
    for r in records:
        if r["method"] in exact:
            assert r["status"] == "PASS" and r["max_error"] <= 1e-10, r
    assert status["master-slave"] == "exempt"
    assert "FAILED" not in status.values()
    comm.Barrier()
    assert len(json.loads(out.read_text())) == len(records)
    demo.EXPECTED_TO_PASS = {*demo.EXPECTED_TO_PASS, ("bridging", False)}
    with pytest.raises(SystemExit) as e:
        demo.main(["--method", "bridging", "--mesh", "regular"])
    assert e.value.code == 1


def test_missing_mesh_names_the_generator(capsys):
    demo = load_demo("patch_test")
    with pytest.raises(SystemExit):
        demo.main(["--method", "fe", "--mesh", "irregular", "--cells", "5"])
    assert "meshes/make_meshes.py --cells 5" in capsys.readouterr().err


def test_dense_gauss_preset_reaches_the_gauss_target_without_vci():
    """``--preset dense-gauss`` (quartic weight, d_max 3, Gauss degree 49): EFG and the Lagrange
    coupling meet the 1e-6 Gauss target without VCI on the gmsh quadrilaterals (measured
    6.2e-7 and 8.8e-8; 1.2e-4 to 6e-4 at the defaults), and the demo holds them to it."""
    demo = load_demo("patch_test")
    for method in ("efg", "lagrange"):
        rec = demo.main(["--method", method, "--mesh", "irregular", "--preset", "dense-gauss"])
        assert (rec["weight"], rec["dilation"], rec["quadrature_degree"]) == ("quartic", 3.0, 49)
        assert rec["preset"] == "dense-gauss" and rec["consistent"] is False
        assert rec["target"] == 1e-6 and rec["expected_to_pass"]
        assert rec["max_error"] <= 1e-6
        assert rec["status"] == "PASS"


def test_dense_gauss_preset_expectations():
    """Without the preset, or with one of its settings overridden, a Gauss miss is reported
    (MISSED, exit 0); under the preset's own settings a miss fails the demo."""
    demo = load_demo("patch_test")
    rec = demo.main(["--method", "lagrange", "--mesh", "irregular"])
    assert (rec["dilation"], rec["quadrature_degree"], rec["preset"]) == (2.0, 7, None)
    assert rec["status"] == "MISSED" and not rec["expected_to_pass"]
    rec = demo.main(["--method", "lagrange", "--mesh", "irregular", "--preset", "dense-gauss",
                     "--quadrature-degree", "7"])  # fmt: skip
    assert (rec["dilation"], rec["quadrature_degree"]) == (3.0, 7)
    assert rec["status"] == "MISSED" and not rec["expected_to_pass"]
    # a preset that no longer reaches the target (4 x 4 Gauss) must fail the run
    demo.PRESETS = {"dense-gauss": {**demo.PRESETS["dense-gauss"], "quadrature_degree": 7}}
    with pytest.raises(SystemExit) as e:
        demo.main(["--method", "lagrange", "--mesh", "irregular", "--preset", "dense-gauss"])
    assert e.value.code == 1
