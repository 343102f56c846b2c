"""docs/python-api.md is the page scripts/gen_python_api.py writes from today's package."""

import importlib.util

import hbn


def test_the_api_page_is_current(repo):
    spec = importlib.util.spec_from_file_location("gen_python_api", repo / "scripts" / "gen_python_api.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    fresh = gen.render(hbn)
    page = repo / "docs" / "python-api.md"
    committed = page.read_text() if page.exists() else ""
    assert committed == fresh, (
        "docs/python-api.md differs from the package's signatures and docstrings: "
        "run python3 scripts/gen_python_api.py (with the wheel installed) and commit the page"
    )
