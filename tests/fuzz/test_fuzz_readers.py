"""The fuzz suite of every reader: seeded mutations of small generated inputs must end in a
typed slamkit error naming the file (and the line where there is one) or in a physically
plausible result (fuzzcases.plausibility_problems); the quirks of real logs must be read,
repaired and counted. See docs/fuzzing.md.

CI runs ``SLAMKIT_FUZZ_N`` (default 150) mutations per reader; ``pytest -m long tests/fuzz``
runs 2,000 per reader; ``tests/fuzz/count.py`` prints the table of the long mode.
"""

from __future__ import annotations

import os
from collections import Counter

import numpy as np
import pytest
from fuzzcases import (
    DEFECTS,
    OUTCOMES,
    cases,
    check_valid,
    judge,
    mutate,
    non_finite_paths,
    plausibility_problems,
    write_files,
)
from fuzztargets import all_targets

from slamkit.datasets.stream import Dataset

TARGETS = {t.name: t for t in all_targets()}
N_CI = int(os.environ.get("SLAMKIT_FUZZ_N", "150"))
N_LONG = 2000


def _run(name: str, n: int, seed: int) -> Counter[str]:
    counts: Counter[str] = Counter()
    defects = []
    for outcome in cases(TARGETS[name], n, seed):
        counts[outcome.kind] += 1
        if outcome.kind in DEFECTS:
            defects.append(f"{outcome.kind} [{outcome.mutation} of {outcome.file}]: "
                           f"{outcome.detail}")  # fmt: skip
    assert not defects, "\n".join(defects[:10])
    assert sum(counts.values()) == n
    return counts


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_the_unmutated_input_loads_with_finite_arrays(name: str) -> None:
    result = check_valid(TARGETS[name])
    assert non_finite_paths(result) == []
    if isinstance(result, Dataset):
        assert sum(result.counts().values()) >= 4  # something to fuzz: events were read


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_mutations_end_typed_or_valid(name: str) -> None:
    counts = _run(name, N_CI, seed=0)
    # The mutations reach the parser: most are caught, and some still load (the fuzzing is
    # not all rejected at the door, nor all harmless).
    assert counts["typed_line"] + counts["typed_no_line"] >= N_CI // 3
    assert counts["accepted"] >= N_CI // 20


@pytest.mark.long
@pytest.mark.parametrize("name", sorted(TARGETS))
def test_many_mutations_end_typed_or_valid(name: str) -> None:
    _run(name, N_LONG, seed=1)


def test_the_mutator_is_seeded_and_covers_its_kinds() -> None:
    data = b"# header\n1 2.5 3\n4 5 6e-3\n7 8 9\n"
    a = [mutate(np.random.default_rng(s), data, False) for s in range(300)]
    b = [mutate(np.random.default_rng(s), data, False) for s in range(300)]
    assert a == b
    kinds = {k for k, _ in a}
    assert {"byte_flip", "truncate", "bad_number", "separator", "empty"} <= kinds
    assert sum(new != data for _, new in a) >= 250
    import gzip

    gz = gzip.compress(data, mtime=0)
    g = [mutate(np.random.default_rng(s), gz, True)[0] for s in range(400)]
    assert any(k.startswith("bad_gzip") for k in g)


def test_outcome_kinds_are_the_documented_ones() -> None:
    assert set(DEFECTS) <= set(OUTCOMES)


QUIRKY = sorted(name for name, t in TARGETS.items() if t.quirks)


@pytest.mark.parametrize("name", QUIRKY)
def test_every_quirk_is_read_repaired_and_counted(name: str, tmp_path) -> None:
    import gzip

    target = TARGETS[name]
    rel = next(iter(target.files))
    write_files(tmp_path, target.files)
    gz = rel.endswith(".gz")
    text = gzip.decompress(target.files[rel]) if gz else target.files[rel]
    for quirk, mutation in target.quirks.items():
        data = mutation(np.random.default_rng(0), text)
        assert data != text, quirk
        (tmp_path / rel).write_bytes(gzip.compress(data) if gz else data)
        outcome = judge(lambda: target.run(tmp_path), tmp_path / rel, quirk, target.check, True)
        assert outcome.kind == "accepted", f"{quirk}: {outcome.detail}"


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_the_unmutated_input_is_plausible(name: str) -> None:
    result = check_valid(TARGETS[name])
    assert plausibility_problems(result) == []
    check = TARGETS[name].check
    assert check is None or check(result) == []
