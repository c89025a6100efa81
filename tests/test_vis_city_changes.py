"""The changes of a city update in the viewer (issue 32): ``icmapper view`` on a city folder with a
latest update (``changes.geojson``) carries the change report, and the page draws it over the
city map (removed red, added green, moved orange) with a toggle; a city without an update has no
changes layer. The browser part runs in Debian's chromium through Playwright and skips (outside
CI) as ``test_vis_viewer`` says when either is missing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from icmapper.data.types import CLASS_NAMES
from icmapper.vis.viewer import city_viewer_data, write_viewer
from test_vis_viewer import _chromium, _open

TYPES = ("removed", "added", "moved")


def _quiet(*_: object) -> None:
    pass


@pytest.fixture(scope="module")
def cities(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A city map of sim-city:val:0:3 (oracle:low) and a copy of it updated with the same
    routes after changes (seed 1)."""
    from icmapper.city.drives import CitySettings
    from icmapper.city.run import build_city
    from icmapper.city.update_run import update_city
    from icmapper.mapping.config import MapperConfig

    root = tmp_path_factory.mktemp("cities")
    base = root / "base"
    settings = CitySettings("icmapper", "oracle:low", None, MapperConfig().to_dict(), (32, 88))
    build_city(base, ["sim-city:val:0:3"], settings, "60x30", pictures=False, log=_quiet,
               progress=False)  # fmt: skip
    updated = root / "updated"
    shutil.copytree(base, updated)
    update_city(updated, ["sim-city-changed:val:0:3:1"], "oracle:low", log=_quiet,
                progress=False)  # fmt: skip
    return base, updated


def _report(city: Path) -> list[dict]:
    return json.loads((city / "changes.geojson").read_text())["features"]


def _counts(features: list[dict], classes: set[str] | None = None) -> dict[str, int]:
    return {
        t: sum(
            f["properties"]["change"] == t
            and (classes is None or f["properties"]["class"] in classes)
            for f in features
        )
        for t in TYPES
    }


def test_city_data_carries_the_latest_changes(cities: tuple[Path, Path]) -> None:
    base, updated = cities
    assert city_viewer_data(base, with_source=False)["changes"] is None
    data = city_viewer_data(updated, with_source=False)
    ch, features = data["changes"], _report(updated)
    assert ch["update"] == 0 and len(ch["change"]) == len(features) > 0
    assert {t for t, n in _counts(features).items() if n} == set(TYPES)  # every type is there
    for k, f in enumerate(features):
        p = f["properties"]
        assert (ch["change"][k], CLASS_NAMES[ch["cls"][k]], ch["instance"][k], ch["cause"][k]) == (
            p["change"], p["class"], p["instance"], p["cause"]
        )  # fmt: skip
        coords = f["geometry"]["coordinates"]
        expected = len(coords[0]) - 1 if ch["closed"][k] else len(coords)  # a ring repeats one
        assert ch["start"][k + 1] - ch["start"][k] == expected
        before = ch["beforeStart"][k + 1] - ch["beforeStart"][k]
        assert before == (len(p["before"]) if p["change"] == "moved" else 0)


@pytest.fixture(scope="module")
def browser():  # noqa: ANN201
    exe = _chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        yield b
        b.close()


def test_changes_layer_in_a_browser(browser, cities: tuple[Path, Path], tmp_path: Path) -> None:  # noqa: ANN001
    base, updated = cities
    features = _report(updated)
    page, errors = _open(
        browser, write_viewer(city_viewer_data(updated, with_source=False), tmp_path / "u.html")
    )
    assert page.evaluate("icmapperViewer.drawnChanges") == _counts(features)
    for t in TYPES:
        legend = page.locator(f'#layers [data-change="{t}"]').inner_text().strip()
        road = sum(
            f["properties"]["change"] == t and f["properties"]["cause"] == "road" for f in features
        )
        assert legend.startswith(f"{t}: {road} applied")
    # A class off: its changes go with it; the toggle: all of them.
    page.locator('input[data-class="ped_crossing"]').uncheck()
    assert page.evaluate("icmapperViewer.drawnChanges") == _counts(
        features, {"divider", "boundary"}
    )
    page.locator('input[data-class="ped_crossing"]').check()
    box = page.locator('input[data-layer="changes"]')
    assert box.is_checked()
    box.uncheck()
    assert page.evaluate("icmapperViewer.drawnChanges") == dict.fromkeys(TYPES, 0)
    shot_off = page.locator("#map").screenshot()
    box.check()
    assert page.evaluate("icmapperViewer.drawnChanges") == _counts(features)
    shot_on = page.locator("#map").screenshot()
    assert shot_on != shot_off  # the layer changes the picture
    page.screenshot(path=str(tmp_path / "changes.png"))
    assert errors == []
    page.close()

    page, errors = _open(
        browser, write_viewer(city_viewer_data(base, with_source=False), tmp_path / "b.html")
    )
    assert page.evaluate("icmapperViewer.drawnChanges") == dict.fromkeys(TYPES, 0)
    assert page.locator('input[data-layer="changes"]').count() == 0
    assert errors == []
    page.close()
