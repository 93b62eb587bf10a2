"""The HTML report opened in a real headless Chromium: every figure must be decoded and drawn."""

import shutil
import tempfile

import numpy as np
import pytest

from contextrl.analysis import plots
from contextrl.analysis.intervals import Interval
from contextrl.analysis.report import Figure, Section, render

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
pytestmark = pytest.mark.skipif(
    not (CHROMIUM and DRIVER), reason="needs Debian chromium and chromium-driver (make system-deps)"
)


@pytest.fixture(scope="module")
def browser():
    webdriver = pytest.importorskip("selenium.webdriver")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="contextrl-chromium-")
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        f"--user-data-dir={profile}",
    ):
        options.add_argument(flag)
    service = webdriver.ChromeService(executable_path=DRIVER)
    driver = webdriver.Chrome(options=options, service=service)
    yield driver
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)


def rendered_figures(browser, path) -> dict[str, list[int]]:
    """Figure name -> [naturalWidth, naturalHeight, shown width] of every report figure."""
    browser.get(f"file://{path}")
    return browser.execute_script(
        "return Object.fromEntries(Array.from(document.querySelectorAll('img.figure')).map("
        "img => [img.dataset.figure, [img.complete ? img.naturalWidth : 0, img.naturalHeight,"
        " img.getBoundingClientRect().width]]));"
    )


def every_plot() -> list[Figure]:
    rng = np.random.default_rng(0)
    curves = {"hidden": rng.normal(size=(3, 20)).cumsum(1), "concat": rng.normal(size=(3, 20))}
    x, y = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    made = {
        "ecdf": plots.ecdf({"a": rng.normal(size=50), "b": rng.normal(1, 1, 50)}),
        "sensitivity": plots.sensitivity_ecdfs(
            {"length": {0.5: [1, 2, 3], 1.0: [4, 5, 6]}, "gravity": {2.0: [1, 1, 2]}}
        ),
        "curves": plots.training_curves(np.arange(20), curves),
        "histogram": plots.histograms({"a": rng.normal(size=40)}),
        "heatmap": plots.heatmap(
            x, y, x + y, xlabel="length", ylabel="tau", regions=[(0.2, 0.6, 0.2, 0.6)]
        ),
        "radar": plots.radar({"A": {"x": 1, "y": 2, "z": 3}, "B": {"x": 3, "y": 1, "z": 0}}),
        "intervals": plots.intervals(
            {"a": {"mean": Interval(1, 0, 2)}, "b": {"mean": Interval(2, 1, 3)}}
        ),
        "bars": plots.bars({"one": 1.0, "two": 3.0}, ylabel="gap"),
        "scatter": plots.scatter([1, 2, 3], {"gap": [0.5, -1, 2]}, xlabel="length", ylabel="gap"),
        "return_vs_feature": plots.return_vs_feature(
            {"hidden": ([0.1, 0.5, 1.0], rng.normal(size=(3, 3)))},
            xlabel="length",
            train_range=(0.25, 0.75),
        ),
    }
    return [Figure(name, plots.to_png(figure), f"the {name} plot") for name, figure in made.items()]


def test_every_plot_renders_in_the_browser(browser, tmp_path):
    figures = every_plot()
    html = render(
        "all plots",
        [Section("Plots", ["text"], [("table", [{"a": 1.5, "b": "x"}])], figures)],
        {"seed": 0},
    )
    assert "http://" not in html and "https://" not in html  # self-contained
    path = tmp_path / "report.html"
    path.write_text(html)
    shown = rendered_figures(browser, path)
    assert sorted(shown) == sorted(f.name for f in figures)
    for name, (width, height, box) in shown.items():
        assert width > 100 and height > 100 and box > 0, name
    assert browser.find_element("id", "metadata").text.startswith("Run metadata")


def test_a_broken_figure_is_detected(browser, tmp_path):
    broken = Figure("broken", b"not a png", "broken")
    path = tmp_path / "report.html"
    path.write_text(render("broken", [Section("S", figures=[broken])], {}))
    assert rendered_figures(browser, path)["broken"][0] == 0


def test_a_run_report_renders(browser, tmp_path):
    from contextrl.experiments import run_experiment

    run, _ = run_experiment(
        {"protocol": "tabular", "num_random": 2}, out=tmp_path / "run", progress=False
    )
    shown = rendered_figures(browser, run.path / "report.html")
    assert set(shown) == {"tabular-gaps"}
    assert shown["tabular-gaps"][0] > 100
    headings = [h.text for h in browser.find_elements("tag name", "h2")]
    assert headings == ["Summary", "Tabular cMDPs", "Spec", "Run metadata"]


def test_a_wide_table_or_long_line_never_scrolls_the_page_sideways(browser, tmp_path):
    """A table of many columns (a run varying many features) and a long line of metadata stay inside
    the page at 1,280 px: the table scrolls in its own box, the line wraps."""
    wide = [{f"feature_{i}": 123456.789 for i in range(40)}]
    code = "x" * 400 + " " + "/a/long/path/" * 40
    path = tmp_path / "report.html"
    path.write_text(render("wide", [Section("S", ["text"], [("wide", wide)], code=code)], {}))
    browser.set_window_size(1280, 900)
    browser.get(f"file://{path}")
    page, viewport = browser.execute_script(
        "return [document.documentElement.scrollWidth, document.documentElement.clientWidth];"
    )
    assert page <= viewport
