"""Every example in the package's docstrings runs and prints what it says (the docstrings are
the Rust doc comments of the native functions and the Python wrappers' own)."""

import doctest

import numpy as np

import ambid


def documented():
    objs = [(n, getattr(ambid, n)) for n in ambid.__all__ if n != "__version__"]
    objs += [(f"Model.{m}", getattr(ambid.Model, m)) for m in dir(ambid.Model) if not m.startswith("_")]
    return [(n, o.__doc__) for n, o in objs if isinstance(getattr(o, "__doc__", None), str)]


def test_docstring_examples_run():
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    ran = []
    for name, doc in documented():
        if ">>>" not in doc:
            continue
        test = parser.get_doctest(doc, {"np": np, "ambid": ambid}, name, None, 0)
        runner.run(test)
        ran.append(name)
    assert runner.failures == 0, f"{runner.failures} failing example(s), see the output above"
    # the public functions carry examples (the lists in docs/python.md)
    for must in ("simulate", "truth", "frf", "periodic_frf", "spectra", "frf_local", "order_scan",
                 "fit_arx", "fit_pem", "fit_ss", "n4sid", "fit_frf", "ss", "validate", "excite",
                 "machine_experiments", "frf_mimo", "bla", "bla_study", "amplitude_study", "run"):
        assert must in ran, f"{must} has no example"
