"""The process's caches are gathered in epa.core.runtime, and reset() empties every one of them."""

import logging
import platform
import subprocess
import sys

import numpy as np
import pytest

from epa.artifacts import case
from epa.core import runtime
from epa.outputs import figures, provenance
from epa.outputs.tables import cells
from epa.workflow import jobs
from epa.workflow.stages import load, metrics


def test_reset_empties_every_cache():
    assert set(runtime.names()) >= {
        "artifacts.case.parsed",
        "artifacts.case.written",
        "workflow.stages.load.loaded",
        "workflow.stages.metrics.printed",
        "outputs.figures.kept",
        "outputs.tables.cells.index",
        "workflow.jobs.inside",
        "workflow.jobs.pool",
        "outputs.provenance.hashed",
    }
    epa_log = logging.getLogger("epa")
    before = (epa_log.propagate, epa_log.level)

    class Pool:  # stands for the worker pool: reset() shuts it down
        closed = False

        def shutdown(self, wait):
            Pool.closed = wait

    case._PARSED["key"] = "trajectory"
    case._WRITTEN["source"] = "path"
    load._LOADED["source"] = "trajectory"
    metrics._PRINTED["source"] = "trajectory"
    provenance._HASHED["key"] = "digest"
    figures._KEPT[("kind",)] = "figure"
    cells.ok_runs([], "alg")  # indexes this grid
    jobs._POOL = Pool()
    jobs._enter_logging()
    assert cells._INDEX and not epa_log.propagate

    runtime.reset()

    assert not case._PARSED and not case._WRITTEN and not load._LOADED and not metrics._PRINTED
    assert not figures._KEPT and not cells._INDEX and not provenance._HASHED
    assert jobs._POOL is None and Pool.closed
    assert jobs._INSIDE["n"] == 0 and (epa_log.propagate, epa_log.level) == before
    runtime.reset()  # twice is harmless


def test_register_takes_a_cache_or_a_reset_function():
    with pytest.raises(TypeError):
        runtime.register("x", {}, reset=lambda: None)
    with pytest.raises(TypeError):
        runtime.register("x")


def test_both_runs_the_second_in_a_thread_only_with_a_spare_core():
    import threading

    def name():
        return threading.current_thread().name

    assert runtime.both(name, name) == (name(), name())
    runtime.use_spare_thread()
    try:
        first, second = runtime.both(name, name)
        assert first == name() and second != first
        with pytest.raises(ZeroDivisionError):  # the second's error, in the caller's thread
            runtime.both(name, lambda: 1 / 0)
    finally:
        runtime.reset()
    assert not runtime.spare_thread()


def test_the_load_stage_reads_ahead_only_a_large_text_with_a_spare_core(tmp_path):
    big = tmp_path / "big.txt"
    big.write_bytes(b"1 0 0 0 0 0 0 1\n" * (load.text.ARROW_MIN_BYTES // 16 + 1))
    assert load.read_ahead(big) is None
    runtime.use_spare_thread()
    try:
        assert load.read_ahead(tmp_path / "missing.txt") is None
        ahead = load.read_ahead(big)
        assert ahead is not None
        ahead.join()  # its thread ends here, not during a later test
    finally:
        runtime.reset()


def test_epa_eval_of_a_bad_reference_leaves_no_read_ahead_thread(tmp_path, capsys):
    """The estimate's parse started beside the reference ends with the load stage, even when the
    reference is refused first (else its thread would parse on, its outcome dropped)."""
    import threading

    from epa.cli.main import main

    (tmp_path / "ref.txt").write_text("0 0 0 0 0 0 0 1\nnot a number\n")
    rows = np.arange(80_000) * 0.01
    big = "".join(f"{t:.2f} {t:.6f} 0 0 0 0 0 1\n" for t in rows)
    assert len(big) > load.text.ARROW_MIN_BYTES
    (tmp_path / "est.txt").write_text(big)
    try:
        assert (
            main(
                [
                    "eval",
                    str(tmp_path / "ref.txt"),
                    str(tmp_path / "est.txt"),
                    "--out",
                    str(tmp_path / "out"),
                ]
            )
            == 2
        )
    finally:
        runtime.reset()
    assert "ref.txt" in capsys.readouterr().err
    assert not [t for t in threading.enumerate() if t.name == "epa-read-ahead"]


def test_a_kept_cache_holds_small_values_beyond_cache_max_and_large_ones_up_to_its_bytes(
    monkeypatch,
):
    """A large grid's batch visits each of its datasets in turn: more references than CACHE_MAX,
    each small, stay parsed; large ones are let go beyond CACHE_MAX once they pass CACHE_BYTES."""
    import numpy as np

    monkeypatch.setattr(case, "CACHE_MAX", 2)
    monkeypatch.setattr(case, "CACHE_MOST", 5)
    monkeypatch.setattr(case, "CACHE_BYTES", 1000)
    kept = case.Kept()
    for k in range(4):
        case.remember(kept, k, np.zeros(10))  # 80 bytes each
    assert list(kept) == [0, 1, 2, 3]
    for k in range(4, 8):
        case.remember(kept, k, np.zeros(10))
    assert list(kept) == [3, 4, 5, 6, 7]  # CACHE_MOST
    case.remember(kept, "large", (np.zeros(200), None))  # 1600 bytes: only CACHE_MAX stay
    assert list(kept) == [7, "large"] and set(kept.sizes) == {7, "large"}
    plain = case.OrderedDict()  # another cache: CACHE_MAX entries
    for k in range(4):
        case.remember(plain, k, np.zeros(10))
    assert list(plain) == [2, 3]
    kept.clear()
    assert not kept and not kept.sizes


_RSS_AFTER_FREE = """
import sys
import numpy as np
from epa.core import runtime
applied = runtime.keep_freed_memory() if sys.argv[1] == "keep" else False
def rss_mb():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096 / 1e6
before = rss_mb()
a = np.ones(24_000_000 // 8)  # a 1M-pose (N, 3) temporary
del a
print(applied, rss_mb() - before)
"""


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="glibc's malloc only",
)
def test_keep_freed_memory_keeps_a_freed_large_array_for_reuse():
    """Without it glibc returns a 24 MB temporary to the system at once (the next one comes as
    fresh pages, zeroed by the kernel); with it the pages stay in the process for the next one
    (also where an older glibc caps the mmap threshold at 32 MiB)."""
    out = _each_mode(_RSS_AFTER_FREE, ("keep", "default"))
    assert out["keep"][0] == "True" and float(out["keep"][1]) > 20
    assert out["default"][0] == "False" and float(out["default"][1]) < 4


def _each_mode(script: str, modes: tuple[str, ...]) -> dict[str, list[str]]:
    """``script``'s printed words in a new Python per mode (its argument)."""
    return {
        mode: subprocess.run(
            [sys.executable, "-c", script, mode], capture_output=True, text=True, check=True
        ).stdout.split()
        for mode in modes
    }


_THREAD_FREED = """
import sys
import threading
import numpy as np
from epa.core import runtime
runtime.keep_freed_memory()
applied = runtime.one_arena() if sys.argv[1] == "one" else False
def rss_mb():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096 / 1e6
def parse():  # a read-ahead thread's 24 MB temporary, freed there
    a = np.ones(24_000_000 // 8)
    del a
thread = threading.Thread(target=parse)
thread.start()
thread.join()
before = rss_mb()
b = np.ones(24_000_000 // 8)  # the main thread's next temporary of that size
print(applied, rss_mb() - before)
"""


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="glibc's malloc only",
)
def test_one_arena_lets_the_main_thread_reuse_what_a_second_thread_freed():
    """Without it a thread's freed memory stays in that thread's own heap: the main thread's next
    24 MB temporary comes as 24 MB of fresh pages; with one_arena it reuses the freed pages."""
    out = _each_mode(_THREAD_FREED, ("one", "default"))
    assert out["one"][0] == "True" and float(out["one"][1]) < 4
    assert out["default"][0] == "False" and float(out["default"][1]) > 20
