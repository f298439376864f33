"""The evaluator's GT cache: computed once per key, least recently used entry dropped first."""

from types import SimpleNamespace

from bench import evaluate


def test_gt_cache_reuses_and_evicts_least_recently_used(monkeypatch):
    monkeypatch.setattr(evaluate, "_GT_CACHE", type(evaluate._GT_CACHE)())
    monkeypatch.setattr(evaluate, "_GT_CACHE_SIZE", 3)
    calls: list[str] = []

    def get(name: str) -> str:
        scene = SimpleNamespace(root=None, name=name)
        return evaluate._cached_gt("scannet", scene, evaluate.LLFFParams("zero"), (), lambda: calls.append(name) or f"gt-{name}")

    assert [get(n) for n in "abc"] == ["gt-a", "gt-b", "gt-c"]
    assert get("a") == "gt-a" and calls == ["a", "b", "c"]  # a hit: nothing recomputed
    get("d")  # full: drops b, the least recently used (a was just used)
    assert len(evaluate._GT_CACHE) == 3
    get("a"), get("c"), get("d")
    assert calls == ["a", "b", "c", "d"]
    get("b")
    assert calls == ["a", "b", "c", "d", "b"]


def test_gt_cache_holds_a_dense_table_worker():
    """A worker cycles through 2 ScanNet + 2 Replica scenes x 3 seeds: 10 entries must fit."""
    assert evaluate._GT_CACHE_SIZE >= 2 + 2 * (1 + 3)
