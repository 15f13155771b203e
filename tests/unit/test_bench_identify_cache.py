"""``bench identify`` simulates each database and makes each shared fit once
per run: the same trials and the same model for the same key, a fresh list
for each caller, nothing kept once the run ends."""

import pytest

from telethermal.bench import identify
from telethermal.ident.prepare import from_trials


@pytest.fixture(autouse=True)
def _empty_stores():
    yield
    identify._database.cache_clear()
    identify._shift_session.cache_clear()
    identify._FITS.clear()


def test_a_database_is_simulated_once_and_each_caller_gets_its_own_list():
    a = identify._trials("fingertip-7", 0)
    b = identify._trials("fingertip-7", 0)
    assert a is not b and all(x is y for x, y in zip(a, b)) and len(a) == len(b)
    a.pop()                                        # a caller's list is its own
    assert len(identify._trials("fingertip-7", 0)) == len(b)
    assert identify._database.cache_info().misses == 1
    assert identify._trials("fingertip-7", 1)[0] is not b[0]      # another seed: drawn anew
    assert identify._database.cache_info().misses == 2


def test_a_fit_is_shared_only_for_the_same_data_and_hyper_parameters():
    contacts, _ = from_trials(identify._trials("fingertip-7", 0), max_s=1.0)
    one = identify._fit("effusivity-lda", contacts)
    again, _ = from_trials(identify._trials("fingertip-7", 0), max_s=1.0)   # equal, not the same
    assert identify._fit("effusivity-lda", again) is one
    assert identify._fit("effusivity-lda", contacts.subset(range(len(contacts) - 1))) is not one
    other = identify._fit("effusivity-lda", contacts, threshold=0.5)
    assert other is not one and other.threshold == 0.5


def test_the_run_empties_its_stores_even_when_it_fails(monkeypatch):
    def failing(report, seed, methods, step, sessions=1, **kw):
        identify._trials("fingertip-7", 0)
        identify._FITS["x"] = object()
        raise RuntimeError("stop")

    monkeypatch.setattr(identify, "_run_methods", failing)
    with pytest.raises(RuntimeError, match="stop"):
        identify.run(methods=["effusivity-lda"])
    assert identify._database.cache_info().currsize == 0 and identify._FITS == {}
