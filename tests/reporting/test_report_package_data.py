"""The page's template and style sheet are package data: found through importlib.resources and shipped."""

import tomllib
from importlib import resources
from pathlib import Path

from kalcal.reporting.html import CSS_FILE, PAGE_TEMPLATE, build_page, page_css


def test_template_and_style_are_found_as_package_resources():
    templates = resources.files("kalcal.reporting").joinpath("templates")
    assert templates.joinpath(PAGE_TEMPLATE).is_file()
    assert templates.joinpath(CSS_FILE).is_file()
    assert page_css() == templates.joinpath(CSS_FILE).read_text(encoding="utf-8")


def test_pyproject_ships_the_templates():
    pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
    config = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    assert "templates/*" in config["tool"]["setuptools"]["package-data"]["kalcal.reporting"]
    assert any(dep.replace(" ", "").startswith("jinja2>=") for dep in config["project"]["dependencies"])


def test_the_style_is_inlined_and_template_values_are_escaped_once():
    summary = {
        "scenario": "it's <x> & \"y\"", "settings": {}, "realizations": 10, "seed": 1, "engine": "exact",
        "confidence": 0.99, "tests": [], "kalcal_version": "0.1",
    }
    page = build_page(summary, [])
    assert f"<style>\n{page_css()}</style>" in page
    assert "<title>kalcal verification report: it&#x27;s &lt;x&gt; &amp; &quot;y&quot;</title>" in page
    assert "&amp;lt;" not in page and "&amp;amp;" not in page
    assert page.endswith("</html>\n")
