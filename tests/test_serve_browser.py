"""``clothsim serve`` in a real headless browser (Debian's Chromium through Selenium and chromedriver).

Skipped, with the reason, where no browser is installed; CI installs one (.ci/run). Set
CLOTHSIM_SERVE_SCREENSHOT=path.png to keep the screenshot of the page that the last test takes
(docs/serve.png, shown in docs/serve.md, is one).
"""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("aiohttp", reason="the serve tests need the 'serve' extra (aiohttp)")
pytest.importorskip("selenium", reason="the browser tests need selenium (in the test extra)")

from conftest import SCENES  # noqa: E402
from serve_support import CHROMEDRIVER, CHROMIUM, NO_BROWSER, ServerThread, chromium  # noqa: E402

# One worker runs the module, in file order, with one server and one browser: the tests share the
# page and each leaves it as the next expects (pytest-xdist's --dist loadgroup).
pytestmark = [pytest.mark.skipif(CHROMIUM is None or CHROMEDRIVER is None, reason=NO_BROWSER),
              pytest.mark.xdist_group("browser")]

SIZE = (384, 384)
SCREENSHOT_ENV = "CLOTHSIM_SERVE_SCREENSHOT"


def wait_until(test, timeout: float = 90.0, what: str = "condition"):  # noqa: ANN001, ANN201
    deadline = time.monotonic() + timeout
    while True:
        value = test()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def served():
    with ServerThread("pinned2", size=SIZE, samples=4) as st:
        driver = chromium()
        try:
            driver.get(st.url)
            yield st, driver
        finally:
            driver.quit()


def text(driver, element_id: str) -> str:  # noqa: ANN001
    from selenium.webdriver.common.by import By

    return driver.find_element(By.ID, element_id).text


def frame_number(driver) -> int:  # noqa: ANN001
    value = text(driver, "frame-number")
    return int(value) if value.lstrip("-").isdigit() else -1


def canvas_image(driver) -> np.ndarray:  # noqa: ANN001
    """What the page shows: a screenshot of the canvas element, as the browser drew it."""
    from selenium.webdriver.common.by import By

    png = driver.find_element(By.ID, "frame").screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def press(driver, key: str) -> None:  # noqa: ANN001
    from selenium.webdriver.common.action_chains import ActionChains

    driver.execute_script("document.activeElement && document.activeElement.blur()")
    ActionChains(driver).send_keys(key).perform()


def pause(st, driver) -> None:  # noqa: ANN001
    if not st.engine.running:
        return
    press(driver, "p")
    wait_until(lambda: text(driver, "run-state") == "paused", what="the page to say paused")


def test_the_page_shows_a_non_blank_changing_image(served):
    st, driver = served
    wait_until(lambda: frame_number(driver) >= 1, what="the first frame")
    first_number, first = frame_number(driver), canvas_image(driver)
    assert first.shape[:2] == SIZE[::-1]
    assert first.std() > 10  # a cloth, not a flat background
    wait_until(lambda: frame_number(driver) >= first_number + 40, what="40 more frames")
    later = canvas_image(driver)
    assert np.abs(later - first).mean() > 0.5
    assert text(driver, "scene-name") == "pinned2" and float(text(driver, "fps")) > 0
    assert text(driver, "error") == ""


def test_p_freezes_the_frame_number_n_advances_one_r_goes_back_to_zero(served):
    st, driver = served
    wait_until(lambda: frame_number(driver) >= 1, what="the first frame")
    pause(st, driver)
    frozen = wait_until(lambda: frame_number(driver) == st.engine.simulation.frame and frame_number(driver),
                        what="the last frame before the pause")
    time.sleep(1.0)
    assert frame_number(driver) == frozen == st.engine.simulation.frame
    press(driver, "n")
    wait_until(lambda: frame_number(driver) != frozen, what="the stepped frame")
    time.sleep(0.5)
    assert frame_number(driver) == frozen + 1 == st.engine.simulation.frame
    press(driver, "r")
    wait_until(lambda: frame_number(driver) == 0, what="frame 0")
    time.sleep(0.5)
    assert frame_number(driver) == 0 == st.engine.simulation.frame
    press(driver, "p")
    wait_until(lambda: frame_number(driver) > 2, what="the simulation to run again")


def test_moving_the_ks_slider_changes_the_servers_simulation(served):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    st, driver = served
    before = st.engine.simulation.ks
    slider = driver.find_element(By.ID, "ks")
    for _ in range(10):  # ten steps of the logarithmic slider, as a keyboard user moves it
        slider.send_keys(Keys.ARROW_LEFT)
    shown = 10 ** float(slider.get_attribute("value"))  # the slider is logarithmic
    wait_until(lambda: st.engine.simulation.ks == pytest.approx(shown, rel=1e-5), what="the server's ks")
    ks = st.engine.simulation.ks
    assert ks < before
    box = driver.find_element(By.CSS_SELECTOR, '[data-for="ks"]')
    assert float(box.get_attribute("value")) == pytest.approx(ks, rel=1e-5)
    st.engine.submit("set", field="ks", value=before).result(30)


def test_switching_the_shader_changes_the_image(served):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    st, driver = served
    pause(st, driver)
    try:
        time.sleep(0.5)

        def saturation(image: np.ndarray) -> float:
            return float((image.max(axis=2) - image.min(axis=2)).mean())

        grey = saturation(canvas_image(driver))
        Select(driver.find_element(By.ID, "shader")).select_by_value("normal")
        wait_until(lambda: st.engine.settings.shader == "normal", what="the server's shader")
        # The normal look colours the cloth by its normals, grey Blinn-Phong does not: whichever way
        # the cloth faces, its pixels are far more saturated. (Waiting for "the image changed", or
        # for red against blue, depended on how far the cloth had fallen when the test ran.)
        wait_until(lambda: saturation(canvas_image(driver)) > grey + 5, what="the normal-shaded image")
        Select(driver.find_element(By.ID, "shader")).select_by_value("phong")
        wait_until(lambda: st.engine.settings.shader == "phong", what="phong again")
    finally:
        press(driver, "p")  # running again, whatever happened: the module's other tests need frames


def test_drag_rotates_ctrl_drag_pans_the_wheel_zooms_and_space_resets(served):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    st, driver = served
    orbit = st.engine.orbit
    start = (orbit.azimuth, orbit.elevation, orbit.distance)
    canvas = driver.find_element(By.ID, "frame")
    ActionChains(driver).move_to_element(canvas).click_and_hold().move_by_offset(80, 30).release().perform()
    wait_until(lambda: orbit.azimuth < start[0] and orbit.elevation > start[1], what="the view to turn")
    ActionChains(driver).move_to_element(canvas).key_down(Keys.CONTROL).click_and_hold().move_by_offset(40, 0) \
        .release().key_up(Keys.CONTROL).perform()
    wait_until(lambda: np.linalg.norm(orbit.offset) > 0, what="the view to pan")
    ActionChains(driver).scroll_from_origin(ScrollOrigin.from_element(canvas), 0, -200).perform()
    wait_until(lambda: orbit.distance < start[2], what="the view to zoom in")
    press(driver, " ")
    wait_until(lambda: st.engine.orbit is not orbit, what="the camera to reset")
    reset = st.engine.orbit
    assert (reset.azimuth, reset.elevation, reset.distance) == start and not reset.offset.any()


def test_a_request_without_the_token_gets_403(served):
    st, driver = served
    script = """
        const done = arguments[arguments.length - 1];
        Promise.all(["/", "/image.png", "/clip", "/?token=wrong"].map(
            (u) => fetch(u).then(async (r) => [r.status, await r.text()])))
          .then(done, (e) => done(String(e)));
    """
    assert driver.execute_async_script(script) == [[403, ""]] * 4


def test_a_bad_uploaded_scene_shows_its_error_and_the_simulation_goes_on(served, tmp_path):
    from selenium.webdriver.common.by import By

    st, driver = served
    sim = st.engine.simulation
    scene = json.loads((SCENES / "pinned2.json").read_text())
    scene["cloth"]["num_width_points"] = 1
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(scene))
    driver.find_element(By.ID, "upload").send_keys(str(bad))
    error = wait_until(lambda: text(driver, "error"), what="the error line")
    assert error == "bad.json: cloth.num_width_points: must be >= 2, got 1"
    assert st.engine.simulation is sim
    running_from = frame_number(driver)
    wait_until(lambda: frame_number(driver) > running_from, what="frames after the bad upload")


def test_a_good_upload_and_a_bundled_scene_load_and_the_screenshot(served, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    st, driver = served
    scene = json.loads((SCENES / "pinned4.json").read_text())
    scene["cloth"]["ks"] = 1234
    good = tmp_path / "my_cloth.json"
    good.write_text(json.dumps(scene))
    # the page leaves alone a field the user is typing in: an earlier test may have left one focused
    driver.execute_script("if (document.activeElement) document.activeElement.blur();")
    driver.find_element(By.ID, "upload").send_keys(str(good))
    wait_until(lambda: text(driver, "scene-name") == "my_cloth.json", what="the uploaded scene")
    assert st.engine.simulation.ks == 1234
    assert float(driver.find_element(By.CSS_SELECTOR, '[data-for="ks"]').get_attribute("value")) == 1234

    Select(driver.find_element(By.ID, "scene")).select_by_value("sphere")
    wait_until(lambda: text(driver, "scene-name") == "sphere", what="the sphere scene", timeout=180)
    wait_until(lambda: frame_number(driver) >= 120, what="the cloth to drape", timeout=180)
    image = canvas_image(driver)
    assert image.std() > 10
    path = os.environ.get(SCREENSHOT_ENV)
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(path)
