"""The public API: every parameter named with its type and the library's own default, one name
per setting across Rust, the CLI and Python, stubs that match the runtime, deprecated names."""

import ast
import inspect
import json
import re
import subprocess
import warnings

import pytest

import hbn
from hbn import _hbn
from conftest import find_hbn_bin

STUB = hbn.__file__.replace("__init__.py", "__init__.pyi")
NATIVE_STUB = hbn.__file__.replace("__init__.py", "_hbn.pyi")
TRAINING = tuple(_hbn.training_keywords())


def frozen(v):
    """A default as a signature shows it (lists as tuples)."""
    return tuple(frozen(i) for i in v) if isinstance(v, list) else v


def public_callables():
    """Every public function, class constructor and public method of ``hbn``:
    ``(qualified name, callable)``."""
    out = []
    for name in hbn.__all__:
        obj = getattr(hbn, name)
        if inspect.isfunction(obj):
            out.append((name, obj))
        elif inspect.isclass(obj) and obj.__module__ == "hbn" and not issubclass(obj, Exception):
            if obj.__init__ is not object.__init__ and "__init__" in vars(obj):
                out.append((f"{name}.__init__", obj.__init__))
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                if isinstance(member, (classmethod, staticmethod)):
                    out.append((f"{name}.{attr}", getattr(obj, attr)))
                elif inspect.isfunction(member):
                    out.append((f"{name}.{attr}", member))
    return out


def test_no_public_callable_hides_its_parameters():
    names = [n for n, _ in public_callables()]
    assert "HysteresisModel.fit" in names and "HysteresisModel.from_logs" in names
    assert "Explorer.__init__" in names and "GaussianProcess.__init__" in names
    for name, f in public_callables():
        for p in inspect.signature(f).parameters.values():
            assert p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL), f"{name}(*{p.name})"


CALLABLES = {
    "fit": hbn.HysteresisModel.fit,
    "from_logs": hbn.HysteresisModel.from_logs,
    "Explorer": hbn.Explorer.__init__,
}


@pytest.mark.parametrize("name", sorted(CALLABLES))
def test_every_training_parameter_is_named_with_the_librarys_default(name):
    params = inspect.signature(CALLABLES[name]).parameters
    assert set(TRAINING) <= set(params), set(TRAINING) - set(params)
    defaults = hbn.default_params()
    for k in TRAINING:
        if name == "from_logs" and k == "rate_hz":
            # The grid rate of the logs (a log option): None, the native rate of the input.
            assert params[k].default is hbn.default_log_options()["rate_hz"] is None
            continue
        if name == "Explorer" and k == "seed":
            assert params[k].default == hbn.default_explore_params()["seed"]
            continue
        assert params[k].default == frozen(defaults[k]), k
        # Keyword-only, except the rate (and the explorer's seed), which come after the data.
        if k != "rate_hz":
            assert params[k].kind == params[k].KEYWORD_ONLY, k


def test_defaults_agree_with_rusts_serialised_defaults():
    """``default_params()`` reads ``HbnParams::default()`` back through ``HbnParams::get``;
    serde's JSON of the same struct is a second, independent reading."""
    j = json.loads(_hbn.default_params_json())
    sel = j["select"]
    expected = {
        "rate_hz": j["rate_hz"],
        "kernel": None if j.get("kernel_evidence") else j["transition_kernel"]["family"],
        "transition_kernel": None if j.get("kernel_evidence") else j["transition_kernel"]["family"],
        "sensor_kernel": None if j.get("kernel_evidence") else j["sensor_kernel"]["family"],
        "n_inducing": (j["n_inducing"], *sel["inducing"]) if sel["inducing"] else j["n_inducing"],
        "max_points": j["max_points"],
        "subset_policy": j["subset_policy"],
        "n_starts": j["n_starts"],
        "max_iters": j["max_iters"],
        "seed": j["seed"],
        "normalize": j["normalize"],
        "noise_floor": j["noise_floor"],
        "blr_window": j["blr_window"],
        "validation": j["validation"],
        "memory": tuple(j["memory"]),
        "lags": (
            (tuple(j["lags"]), *(tuple(s) for s in sel["lags"]))
            if sel.get("lags")
            else tuple(j["lags"])
        ),
        "linear_mean": j["linear_mean"],
        "sensor_inputs": (
            (j.get("sensor_inputs", "thesis"), *sel["sensor_inputs"])
            if sel.get("sensor_inputs")
            else j.get("sensor_inputs", "thesis")
        ),
        "max_signal_variance": j["max_signal_variance"],
        "firmware_budget": j.get("firmware_budget"),
    }
    assert set(expected) == set(TRAINING)
    fit = inspect.signature(hbn.HysteresisModel.fit).parameters
    for k, v in expected.items():
        assert fit[k].default == v, k


def options_table(repo):
    """The rows of docs/options.md's options table: ``{column: cell}`` dicts."""
    text = (repo / "docs" / "options.md").read_text()
    m = re.search(r"<!-- options-table: begin -->\n(.*?)<!-- options-table: end -->", text, re.S)
    assert m, "docs/options.md has no options table (<!-- options-table: begin --> ... end -->)"
    lines = [ln.strip() for ln in m.group(1).strip().splitlines() if ln.strip()]
    cells = lambda ln: [c.strip() for c in ln.strip("|").split("|")]  # noqa: E731
    head = cells(lines[0])
    assert head == ["Option", "CLI flag", "Python keyword", "Rust", "Default"], head
    return [dict(zip(head, cells(ln))) for ln in lines[2:]]


def keyword_of(cell):
    """A Python keyword cell: the keyword in backticks, or None for a dash."""
    if cell in ("—", "-", ""):
        return None
    m = re.fullmatch(r"`([A-Za-z_][A-Za-z0-9_]*)`", cell)
    assert m, f"a Python keyword cell is `keyword` or —, got {cell!r}"
    return m.group(1)


def test_from_logs_takes_exactly_the_options_tables_python_keywords(repo):
    table = {keyword_of(r["Python keyword"]) for r in options_table(repo)} - {None}
    keywords = set(inspect.signature(hbn.HysteresisModel.from_logs).parameters)
    assert keywords == table, (
        f"only in from_logs: {sorted(keywords - table)}; only in docs/options.md: "
        f"{sorted(table - keywords)}"
    )


def help_defaults(exe):
    """``{--flag: default text}`` of ``hbn train --help`` (flags with a clap default)."""
    text = subprocess.run(
        [exe, "train", "--help"], capture_output=True, text=True, check=True
    ).stdout
    out, flag = {}, None
    for line in text.splitlines():
        m = re.match(r"^\s+(?:-\w, )?(--[a-z0-9-]+)", line)
        if m:
            flag = m.group(1)
        d = re.search(r"\[default: (.*)\]", line)
        if d and flag:
            out[flag] = d.group(1)
    return out


def as_cli(v):
    """A Python default as clap prints it."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, tuple):
        return ",".join(as_cli(i) for i in v) if v else "none"
    return str(v)


def same(py, cli):
    if isinstance(py, (int, float)) and not isinstance(py, bool):
        return float(cli) == float(py)
    if isinstance(py, tuple) and py and all(isinstance(i, (int, float)) for i in py):
        return [float(c) for c in cli.split(",")] == [float(i) for i in py]
    return as_cli(py) == cli


def test_signature_defaults_are_hbn_trains(repo):
    """Every option with a clap default has that default in ``from_logs``'s signature (the flag
    found by the options table; ``--no-x`` is the negation of ``x``)."""
    exe = find_hbn_bin()
    if exe is None:
        pytest.skip("no hbn binary: set HBN_BIN or build target/release/hbn")
    defaults = help_defaults(exe)
    params = inspect.signature(hbn.HysteresisModel.from_logs).parameters
    checked = 0
    for row in options_table(repo):
        keyword = keyword_of(row["Python keyword"])
        flag = row["CLI flag"].strip("`")
        if keyword not in params or flag not in defaults:
            continue  # (a keyword from_logs lacks fails the test above)
        py = params[keyword].default
        if flag.startswith("--no-"):
            py = not py
        assert same(py, defaults[flag]), (flag, keyword, defaults[flag], py)
        checked += 1
    assert checked >= 10, checked


def stub_functions(path):
    """``{qualified name: ast.FunctionDef}`` of a stub file (top-level and class methods), and
    the names decorated as properties."""
    tree = ast.parse(open(path).read())
    out, props = {}, set()

    def visit(body, prefix):
        for node in body:
            if isinstance(node, ast.FunctionDef):
                decorators = {getattr(d, "id", getattr(d, "attr", None)) for d in node.decorator_list}
                name = prefix + node.name
                if "property" in decorators:
                    props.add(name)
                elif "overload" in decorators:
                    out.setdefault(name, node)
                else:
                    out[name] = node
            elif isinstance(node, ast.ClassDef):
                visit(node.body, prefix + node.name + ".")

    visit(tree.body, "")
    return out, props


def stub_parameters(node, bound):
    a = node.args
    kinds = inspect.Parameter
    ps = [(x.arg, kinds.POSITIONAL_ONLY) for x in a.posonlyargs]
    ps += [(x.arg, kinds.POSITIONAL_OR_KEYWORD) for x in a.args]
    if a.vararg:
        ps.append((a.vararg.arg, kinds.VAR_POSITIONAL))
    ps += [(x.arg, kinds.KEYWORD_ONLY) for x in a.kwonlyargs]
    if a.kwarg:
        ps.append((a.kwarg.arg, kinds.VAR_KEYWORD))
    return ps[1:] if bound else ps


def runtime_parameters(f):
    return [(p.name, p.kind) for p in inspect.signature(f).parameters.values()]


def test_the_stubs_match_the_runtime():
    stubs, props = stub_functions(STUB)
    for name, f in public_callables():
        assert name in stubs, f"{name} is missing from __init__.pyi"
        bound = inspect.ismethod(f)  # a classmethod, bound to its class
        assert stub_parameters(stubs[name], bound) == runtime_parameters(f), name
    # Nothing in the stubs that the runtime lacks, and every property is one.
    runtime = {n for n, _ in public_callables()}
    for name in stubs:
        owner, _, attr = name.rpartition(".")
        if attr.startswith("__") and attr != "__init__" or attr.startswith("_") and attr != "__init__":
            continue
        if owner and owner not in hbn.__all__:
            continue
        assert name in runtime or (not owner and name in ("default_params",)), name
    for name in props:
        owner, _, attr = name.rpartition(".")
        if owner in hbn.__all__:
            assert isinstance(inspect.getattr_static(getattr(hbn, owner), attr), property), name
    assert set(ast.literal_eval(_all_of(STUB))) == set(hbn.__all__)


def _all_of(path):
    tree = ast.parse(open(path).read())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == "__all__":
            return ast.unparse(node.value)
    raise AssertionError("no __all__ in the stub")


def native_names(f):
    return [p.name for p in inspect.signature(f).parameters.values() if p.name != "self"]


def stub_names(node):
    return [n for n, _ in stub_parameters(node, False) if n not in ("self", "cls")]


def test_the_native_stubs_match_the_native_module():
    stubs, props = stub_functions(NATIVE_STUB)
    tree = ast.parse(open(NATIVE_STUB).read())
    fields = {
        f"{c.name}.{a.target.id}"
        for c in tree.body
        if isinstance(c, ast.ClassDef)
        for a in c.body
        if isinstance(a, ast.AnnAssign)
    }
    for name in (n for n in dir(_hbn) if not n.startswith("_")):
        obj = getattr(_hbn, name)
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            continue
        if inspect.isclass(obj):
            if getattr(obj, "__text_signature__", None):  # a constructor (#[new])
                assert stub_names(stubs[f"{name}.__init__"]) == native_names(obj), name
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                q = f"{name}.{attr}"
                if type(member).__name__ == "getset_descriptor":
                    assert q in props or q in fields, f"{q} is missing from _hbn.pyi"
                else:
                    assert q in stubs, f"{q} is missing from _hbn.pyi"
                    assert stub_names(stubs[q]) == native_names(getattr(obj, attr)), q
        elif callable(obj):
            assert name in stubs, f"{name} is missing from _hbn.pyi"
            assert stub_names(stubs[name]) == native_names(obj), name


def test_errors_name_the_keyword_and_its_value():
    d = hbn.simulate("duhem", 50, seed=1)
    with pytest.raises(hbn.ConfigError) as e:
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], max_points=1)
    assert str(e.value) == "invalid max_points=1: must be at least 2"
    assert e.value.keyword == "max_points"
    with pytest.raises(hbn.ConfigError) as e:
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], kernel="rbf")
    assert str(e.value).startswith("invalid kernel='rbf': choose one of matern52")
    with pytest.raises(hbn.ConfigError) as e:
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], seed=-1)
    assert str(e.value) == "invalid seed=-1: expected a non-negative integer"


def test_renamed_keywords_warn_and_still_work():
    d = hbn.simulate("duhem", 120, seed=1)
    with pytest.warns(DeprecationWarning, match=r"n_restarts=\) is deprecated; use n_starts="):
        gp = hbn.GaussianProcess(n_restarts=2)
    assert gp.n_starts == 2
    with pytest.warns(DeprecationWarning, match="use max_iters="):
        m = hbn.HysteresisModel.fit(
            d["u"], d["x"], d["y"], rate_hz=50.0, max_iter=20, max_points=40, n_starts=1,
            validation=0.0,
        )
    assert m.params["max_iters"] == 20 and m.rate_hz == 50.0
    with pytest.raises(TypeError, match="both n_restarts= and n_starts="):
        hbn.GaussianProcess(n_restarts=2, n_starts=2)
    with pytest.warns(DeprecationWarning, match="rate_hz"):
        assert m.rate == 50.0
    with pytest.warns(DeprecationWarning, match="use rate_hz="):
        assert hbn.simulate("duhem", 5, rate=50.0)["u"].shape == (5,)
    with pytest.warns(DeprecationWarning, match="hbn.HysteresisModel"):
        assert hbn.HbnModel is hbn.HysteresisModel
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hbn.GaussianProcess(n_starts=2)  # the current names do not warn
    with pytest.raises(AttributeError):
        hbn.NoSuchThing  # noqa: B018


def test_unknown_keywords_are_type_errors():
    d = hbn.simulate("duhem", 50, seed=1)
    with pytest.raises(TypeError, match="max_pointz"):
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], max_pointz=10)
    with pytest.raises(TypeError):
        hbn.Explorer(0.0, 1.0, 0.1, n_restart=1)


def test_every_public_item_has_a_docstring():
    missing = [name for name, f in public_callables() if name.split(".")[-1] != "__init__" and not (f.__doc__ or "").strip()]
    for name in hbn.__all__:
        obj = getattr(hbn, name)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            if not (obj.__doc__ or "").strip():
                missing.append(name)
        if inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if isinstance(member, property) and not attr.startswith("_"):
                    if not (member.fget.__doc__ or "").strip():
                        missing.append(f"{name}.{attr}")
    assert not missing, missing
