"""The CLI and the server run numpy's BLAS on one thread (tofpose.core.threads)."""

from __future__ import annotations

from threadpoolctl import threadpool_info, threadpool_limits

from tofpose.cli import main


def _blas_threads() -> set[int]:
    return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_the_cli_limits_blas_to_one_thread(tmp_path, capsys):
    with threadpool_limits(limits=2, user_api="blas"):  # restored afterwards
        assert _blas_threads() == {2}
        assert main(["openapi", "--out", str(tmp_path / "o.json")]) == 0
        assert _blas_threads() == {1}
