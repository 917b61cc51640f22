"""Drives the web page of a running `icms serve` in headless Chromium (Debian's chromium and
chromium-driver, through selenium) and prints one JSON object of what it saw and measured.

Usage: web_page.py BASE_URL SKILL_ID XSS_SKILL_ID SCREENSHOT_DIR
  SKILL_ID      a skill of a real (simulated) session: its forces are plotted and it is replayed
  XSS_SKILL_ID  a skill whose session's scenario is named <script>alert(1)</script>
"""
import json
import os
import shutil
import sys
import time

from selenium import webdriver
from selenium.common.exceptions import NoAlertPresentException, TimeoutException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

base, skill_id, xss_skill_id, shots = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
os.makedirs(shots, exist_ok=True)
XSS = "<script>alert(1)</script>"

options = webdriver.ChromeOptions()
options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1400,1100",
            "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu-vsync"):
    options.add_argument(arg)
options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
driver = webdriver.Chrome(options=options,
                          service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"))
driver.set_page_load_timeout(60)
out = {"console_errors": [], "steps": []}
# Network errors the test provokes on purpose (the invalid hand upload answers 422).
expected = []


def logs(step):
    for entry in driver.get_log("browser"):
        if entry["level"] != "SEVERE":
            continue
        if any(e in entry["message"] for e in expected):
            continue
        out["console_errors"].append({"step": step, "message": entry["message"]})
    out["steps"].append(step)


def wait_ready(name, timeout=60):
    """Waits until the view `name` (or an error) is rendered; call `unready()` before the
    navigation or click that starts it, so a view already on screen does not count."""
    state = WebDriverWait(driver, timeout).until(
        lambda d: (lambda s: s if s in (name, "error") else None)(
            d.execute_script("return document.body.dataset.ready")))
    if state != name:
        err = driver.execute_script("return document.getElementById('error').textContent")
        shot("failure")
        raise SystemExit(f"the page showed an error instead of {name} after steps {out['steps']} "
                         f"at {driver.current_url}: {err.split()}; console: {driver.get_log('browser')}")


def unready():
    driver.execute_script("if (document.body) document.body.dataset.ready = ''")


def go(url):
    """Navigates (a new page or only the hash) and forgets the view on screen."""
    unready()
    driver.get(url)


def shot(name):
    driver.save_screenshot(os.path.join(shots, f"{name}.png"))


def alert_open():
    try:
        driver.switch_to.alert
        return True
    except NoAlertPresentException:
        return False


try:
    # 1. The list: how long after navigation starts the first page of skills is on screen.
    driver.get(base + "/")
    wait_ready("skills")
    out["list_rendered_ms"] = driver.execute_script("return window.icms.listRenderedAt")
    out["list_dom_content_loaded_ms"] = driver.execute_script(
        "return performance.getEntriesByType('navigation')[0].domContentLoadedEventEnd")
    out["list_rows"] = len(driver.find_elements(By.CSS_SELECTOR, "#skill-rows tr"))
    shot("skills")
    logs("list")

    # 2. Filter: boxes, newest first.
    Select(driver.find_element(By.NAME, "shape")).select_by_value("box")
    Select(driver.find_element(By.NAME, "sort")).select_by_value("-id")
    unready()
    driver.find_element(By.ID, "apply").click()
    wait_ready("skills")
    objects = [td.text for td in driver.find_elements(By.CSS_SELECTOR, "#skill-rows td.object")]
    out["filtered_rows"] = len(objects)
    out["filtered_all_box"] = bool(objects) and all(o.startswith("box") for o in objects)
    ids = [int(tr.get_attribute("data-id")) for tr in driver.find_elements(By.CSS_SELECTOR, "#skill-rows tr")]
    out["filtered_sorted_desc"] = ids == sorted(ids, reverse=True)
    out["hash_after_filter"] = driver.execute_script("return location.hash")
    unready()
    driver.find_element(By.ID, "next").click()
    wait_ready("skills")
    ids2 = [int(tr.get_attribute("data-id")) for tr in driver.find_elements(By.CSS_SELECTOR, "#skill-rows tr")]
    out["next_page_continues"] = bool(ids2) and max(ids2) < min(ids)
    shot("skills-filtered")
    logs("filter")

    # 3. A skill: phases, the force plot drawn, contacts in 3D, nearest skills.
    go(f"{base}/#/skills/{skill_id}")
    wait_ready("skill")
    out["timeline_phases"] = len(driver.find_elements(By.CSS_SELECTOR, "#timeline div"))
    out["plot_pixels"] = driver.execute_script("""
        const c = document.querySelector('#plot-normal canvas');
        if (!c) return 0;
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++;
        return n;""")
    out["plot_series"] = len(driver.find_elements(By.CSS_SELECTOR, "#plot-normal .u-series")) - 1
    out["contacts_canvas"] = len(driver.find_elements(By.CSS_SELECTOR, "#contacts3d canvas"))
    out["similar_rows"] = len(driver.find_elements(By.CSS_SELECTOR, "#similar-table tbody tr"))
    shot("skill")
    logs("skill")

    # 4. Replay on a built-in hand and watch it.
    Select(driver.find_element(By.ID, "replay-hand")).select_by_value("allegro")
    driver.find_element(By.ID, "run-replay").click()
    WebDriverWait(driver, 240).until(
        lambda d: d.find_element(By.ID, "replay-player").get_attribute("data-loaded"))
    f0 = driver.execute_script("return window.icms.replayFrame")
    n0 = driver.execute_script("return window.icms.frames")
    t0 = time.monotonic()
    time.sleep(2.0)
    f1 = driver.execute_script("return window.icms.replayFrame")
    n1 = driver.execute_script("return window.icms.frames")
    t1 = time.monotonic()
    out["replay_frames"] = [f0, f1]
    out["replay_advanced"] = f1 != f0
    out["animation_fps"] = (n1 - n0) / (t1 - t0)
    out["replay_listed"] = len(driver.find_elements(By.CSS_SELECTOR, "#replay-list li"))
    out["replay_report"] = "success" in driver.find_element(By.ID, "replay-report").text
    driver.find_element(By.ID, "replay-play").click()
    fa = driver.execute_script("return window.icms.replayFrame")
    time.sleep(0.5)
    out["pause_holds"] = driver.execute_script("return window.icms.replayFrame") == fa
    shot("replay")
    logs("replay")

    # 5. The scenario named <script>alert(1)</script> is shown as text and runs nothing.
    go(f"{base}/#/skills/{xss_skill_id}")
    wait_ready("skill")
    page = driver.find_element(By.TAG_NAME, "main").text
    out["xss_text_on_skill"] = XSS in page
    session_link = driver.find_element(By.CSS_SELECTOR, "a.session-link")
    unready()
    session_link.click()
    wait_ready("session")
    out["xss_text_on_session"] = XSS in driver.find_element(By.ID, "session-scenario").text
    out["xss_alert_session"] = alert_open()
    shot("session")
    go(f"{base}/#/sessions")
    wait_ready("sessions")
    out["xss_alert"] = alert_open()
    out["xss_script_elements"] = driver.execute_script(
        "return [...document.querySelectorAll('main script')].length")
    out["foxglove_links"] = len(driver.find_elements(By.PARTIAL_LINK_TEXT, "open in Foxglove"))
    shot("sessions")
    logs("sessions")

    # 6. Hands: each drawn; an invalid upload shows the problem's title and detail.
    go(f"{base}/#/hands")
    wait_ready("hands")
    WebDriverWait(driver, 30).until(
        lambda d: len(d.find_elements(By.CSS_SELECTOR, ".hand3d canvas")) >= 5)
    out["hand_cards"] = len(driver.find_elements(By.CSS_SELECTOR, "#hands section"))
    out["hand_canvases"] = len(driver.find_elements(By.CSS_SELECTOR, ".hand3d canvas"))
    expected.append("/api/v1/hands - Failed to load resource: the server responded with a status of 422")
    spec = {"name": "bad-hand", "fingertips": [{"name": "thumb", "link": "no_such_link", "offset": [0, 0, 0], "radius": 0.01}],
            "torque_limit": 0.5, "base_link": "palm"}
    driver.find_element(By.NAME, "spec").send_keys(json.dumps(spec))
    driver.find_element(By.NAME, "urdf").send_keys('<robot name="bad"><link name="palm"/></robot>')
    driver.find_element(By.ID, "upload-hand").click()
    WebDriverWait(driver, 30).until(lambda d: d.find_elements(By.ID, "upload-error"))
    out["upload_error"] = driver.find_element(By.ID, "upload-error").text
    out["error_bar"] = driver.find_element(By.ID, "error").text
    shot("hands")
    logs("hands")

    # 7. Not found, and the API documentation.
    driver.get(f"{base}/no/such/page")
    out["not_found_page"] = bool(driver.find_elements(By.ID, "not-found"))
    expected.append("/no/such/page - Failed to load resource: the server responded with a status of 404")
    logs("not-found")
    driver.get(f"{base}/docs")
    WebDriverWait(driver, 60).until(lambda d: d.find_elements(By.CSS_SELECTOR, ".swagger-ui .info .title"))
    out["docs_title"] = driver.find_element(By.CSS_SELECTOR, ".swagger-ui .info .title").text
    out["docs_operations"] = len(driver.find_elements(By.CSS_SELECTOR, ".opblock"))
    shot("docs")
    logs("docs")
except TimeoutException as e:
    out["failure"] = f"timed out after steps {out['steps']}: {e.msg}"
    shot("failure")
finally:
    driver.quit()

print(json.dumps(out))
