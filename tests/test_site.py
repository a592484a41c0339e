"""The documentation site (issue #68): ``mkdocs build --strict`` builds it (broken links,
missing pages and unknown references fail), the config reference page is generated from
the schema at build time, the API page renders ``designopt.api``, and no built page loads
anything from the network (fonts, scripts, stylesheets): the site works offline. One build
for all the checks on the built pages. Also the README as a landing page: short, with the
two set-up commands, and links that resolve in the repository."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import types
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import mkdocs_hooks  # noqa: E402  (tools/ is not a package)

NAV_PAGES = [
    "index.html",
    "getting-started/install.html",
    "getting-started/main-job.html",
    "getting-started/first-robot.html",
    "getting-started/first-planning.html",
    "guides/studies.html",
    "urdf.html",
    "task.html",
    "planning.html",
    "pareto.html",
    "optimizers.html",
    "configs.html",
    "scaling.html",
    "faults.html",
    "reference/config.html",
    "reference/cli.html",
    "reference/api.html",
    "archive.html",
    "indices.html",
    "figures.html",
    "kinematics.html",
    "architecture.html",
    "performance.html",
    "papers.html",
    "plas.html",
    "rcm.html",
    "davinci.html",
    "sphere.html",
    "changelog.html",
]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site as CI builds it: the environment's ``python -m mkdocs build --strict``."""
    out = tmp_path_factory.mktemp("site") / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, (
        f"mkdocs build --strict failed (exit {proc.returncode}):\n{log[-6000:]}"
    )
    assert "WARNING" not in log, log[-6000:]
    return out


def _text(page: Path) -> str:
    """A built page's visible text, tags stripped."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8")))


def test_every_page_of_the_nav_is_built(site):
    missing = [p for p in NAV_PAGES if not (site / p).is_file()]
    assert not missing, f"pages of the nav not built: {missing}"
    home = (site / "index.html").read_text(encoding="utf-8")
    for tab in ("Getting started", "Guides", "Reference", "Performance", "Papers", "Changelog"):
        assert tab in home, f"the navigation has no {tab!r}"
    assert (site / "img" / "planning_naive_vs_best.png").is_file()  # images travel with the pages


def test_the_config_reference_is_generated_from_the_schema(site):
    html = (site / "reference" / "config.html").read_text(encoding="utf-8")
    assert mkdocs_hooks.MARKER not in html and "generated: designopt" not in html
    text = _text(site / "reference" / "config.html")
    for key in ("optimizer.n_particles", "study.task.ik.n_best", "seed", "precision"):
        assert key in text, f"the generated config reference does not list {key}"
    from designopt.app import reference

    first = next(line for line in reference.markdown().splitlines() if line.startswith("| `"))
    key = first.split("`")[1]  # the first key of the first table, as generated
    assert key in text


def test_the_api_page_renders_the_public_functions_and_records(site):
    html = (site / "reference" / "api.html").read_text(encoding="utf-8")
    for name in ("load_config", "run", "sweep", "scan", "evaluate", "load"):
        assert f'id="designopt.api.{name}"' in html, f"designopt.api.{name} is not rendered"
    for record in ("RunRecord", "ScanRecord", "FrontRecord", "IKRecord"):
        assert record in html
    assert "ConfigError" in html
    # a docstring's text, not only the names: load_config's says what overrides are
    assert "dotted keys" in _text(site / "reference" / "api.html")


def test_the_changelog_page_includes_CHANGELOG_md(site):
    text = _text(site / "changelog.html")
    assert "--8<--" not in text
    import tomllib

    with open(ROOT / "pyproject.toml", "rb") as f:
        version = tomllib.load(f)["project"]["version"]
    assert version in text and "0.2.0" in text and "0.1.0" in text


class _Loads(HTMLParser):
    """Every URL a page makes the browser fetch: src of scripts, images, frames and media,
    href of stylesheets, preloads and icons, and url()/@import in inline styles."""

    FETCHED_LINKS = {"stylesheet", "preload", "modulepreload", "prefetch", "icon",
                     "preconnect", "dns-prefetch", "manifest"}  # fmt: skip

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self._style = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("script", "img", "iframe", "source", "audio", "video", "embed", "track"):
            self.urls += [a[k] for k in ("src", "srcset", "poster") if a.get(k)]
        if tag == "link" and set((a.get("rel") or "").split()) & self.FETCHED_LINKS:
            self.urls.append(a.get("href") or "")
        if tag == "style":
            self._style = True
        if a.get("style"):
            self.urls += _css_urls(a["style"])

    def handle_endtag(self, tag):
        if tag == "style":
            self._style = False

    def handle_data(self, data):
        if self._style:
            self.urls += _css_urls(data)


def _css_urls(css: str) -> list[str]:
    return re.findall(r"url\(\s*['\"]?([^'\")]+)", css) + re.findall(
        r"@import\s+['\"]([^'\"]+)", css
    )


def _remote(url: str) -> bool:
    return bool(re.match(r"\s*(?:https?:)?//", url))


def test_no_page_loads_anything_from_the_network(site):
    pages = sorted(site.rglob("*.html"))
    assert len(pages) >= len(NAV_PAGES)
    remote = []
    for page in pages:
        parser = _Loads()
        parser.feed(page.read_text(encoding="utf-8"))
        remote += [f"{page.relative_to(site)}: {u}" for u in parser.urls if _remote(u)]
    for css in site.rglob("*.css"):
        remote += [
            f"{css.relative_to(site)}: {u}" for u in _css_urls(css.read_text()) if _remote(u)
        ]
    assert not remote, "the site fetches from the network:\n" + "\n".join(remote[:20])


def test_the_parser_sees_each_kind_of_remote_load():
    """The offline check would catch a CDN script, a web font's stylesheet, an image and a
    CSS import; a plain link to a web page is not a load."""
    parser = _Loads()
    parser.feed('<script src="https://cdn.example/x.js"></script>'
                '<link rel="stylesheet" href="//fonts.example/css">'
                '<img src="http://example.org/a.png"><style>@import "https://x/y.css";</style>'
                '<a href="https://keepachangelog.com">a link</a><script src="assets/a.js"></script>')  # fmt: skip
    assert [u for u in parser.urls if _remote(u)] == [
        "https://cdn.example/x.js", "//fonts.example/css", "http://example.org/a.png",
        "https://x/y.css"]  # fmt: skip


# ------------------------------------------------------------ the hook, without a build


class _Page:
    def __init__(self, uri: str) -> None:
        self.file = types.SimpleNamespace(src_uri=uri)


PLACEHOLDER = f"# Config keys\n\nintro\n\n{mkdocs_hooks.MARKER}\n"


def test_the_hook_replaces_the_placeholder_page_only():
    from designopt.app import reference

    assert mkdocs_hooks.on_page_markdown("# x\n", _Page("task.md"), None, None) == "# x\n"
    out = mkdocs_hooks.on_page_markdown(PLACEHOLDER, _Page(mkdocs_hooks.PAGE), None, None)
    assert out.strip().endswith(reference.markdown().strip())
    assert mkdocs_hooks.MARKER not in out and out.count("\n# ") + out.startswith("# ") == 1


@pytest.mark.parametrize("broken", ["missing", "raises", "empty"])
def test_the_hook_fails_loudly_without_a_reference(broken, monkeypatch):
    """No generator, a failing one or an empty one fails the build, naming the page."""
    from mkdocs.exceptions import PluginError

    import designopt.app

    if broken == "missing":
        monkeypatch.setitem(sys.modules, "designopt.app.reference", None)  # import fails
        monkeypatch.delattr(designopt.app, "reference", raising=False)
    else:
        fake = types.ModuleType("designopt.app.reference")
        fake.markdown = (lambda: 1 / 0) if broken == "raises" else (lambda: "  \n")
        monkeypatch.setitem(sys.modules, "designopt.app.reference", fake)
        monkeypatch.setattr(designopt.app, "reference", fake, raising=False)
    with pytest.raises(PluginError, match="reference/config.md"):
        mkdocs_hooks.on_page_markdown(PLACEHOLDER, _Page(mkdocs_hooks.PAGE), None, None)


def test_the_hook_fails_when_the_placeholder_lost_its_marker():
    from mkdocs.exceptions import PluginError

    with pytest.raises(PluginError, match="missing"):
        mkdocs_hooks.on_page_markdown("# Config keys\n", _Page(mkdocs_hooks.PAGE), None, None)


# ------------------------------------------------------------ the README as a landing page

SETUP = [
    "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && designopt run "
    "configs/master9.yaml",
    'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && python -m '
    "pytest -q -n auto --dist loadfile",
]


def test_the_readme_is_a_landing_page_with_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    words = len(text.split())
    assert 600 <= words <= 900, f"README.md has {words} words (a landing page: 600-900)"
    lines = [line.strip() for line in text.splitlines()]
    for cmd in SETUP:
        assert cmd in lines, f"README.md lost the set-up command on a line of its own: {cmd}"


def test_the_readmes_relative_links_and_images_exist():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", text)
    local = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert len(local) > 10
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README.md links to files that are not there: {missing}"
