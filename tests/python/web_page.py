"""Drives the web page of a running `icms serve` in a real browser and prints one JSON object of
what it saw and measured. One flow, two browsers:

- chromium: Debian's chromium, headless, through chromium-driver (its console read from the
  driver's browser log);
- firefox: Debian's firefox-esr through geckodriver (Mozilla's Rust crate, which
  scripts/test installs with cargo), with WebDriver BiDi for its console and JavaScript errors.
  Firefox's own -headless mode has no WebGL on a machine without a GPU ("WebGL creation
  failed: tryNativeGL, Exhausted GL driver options"), so Firefox runs on a private Xvfb display
  (Debian's xvfb) where Mesa's llvmpipe gives it WebGL 2, as CI's Chromium has SwiftShader.

Usage: web_page.py BROWSER BASE_URL SKILL_ID XSS_SKILL_ID SCREENSHOT_DIR
  BROWSER       chromium or firefox
  SKILL_ID      a skill of a real (simulated) session: its forces are plotted and it is replayed
  XSS_SKILL_ID  a skill whose session's scenario is named <script>alert(1)</script>
"""
import json
import os
import shutil
import subprocess
import sys
import time

from selenium import webdriver
from selenium.common.exceptions import NoAlertPresentException, TimeoutException
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

browser, base, skill_id, xss_skill_id, shots = sys.argv[1:6]
os.makedirs(shots, exist_ok=True)
XSS = "<script>alert(1)</script>"
WIDTH, HEIGHT = 1400, 1100


class Chromium:
    """Headless Chromium; its console errors from the driver's browser log (SEVERE)."""

    def __init__(self):
        from selenium.webdriver.chrome.service import Service
        options = webdriver.ChromeOptions()
        options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
        for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                    f"--window-size={WIDTH},{HEIGHT}", "--use-angle=swiftshader",
                    "--enable-unsafe-swiftshader", "--disable-gpu-vsync"):
            options.add_argument(arg)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        self.driver = webdriver.Chrome(
            options=options,
            service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"))

    def console_errors(self):
        return [e["message"] for e in self.driver.get_log("browser") if e["level"] == "SEVERE"]

    def quit(self):
        self.driver.quit()


class Firefox:
    """Firefox ESR on a private Xvfb display; console errors (console.error) and uncaught
    exceptions and promise rejections from WebDriver BiDi's log events."""

    def __init__(self):
        # Xvfb picks a free display number and writes it to the pipe.
        read, write = os.pipe()
        self.xvfb = subprocess.Popen(
            ["Xvfb", "-displayfd", str(write), "-screen", "0", f"{WIDTH}x{HEIGHT}x24",
             "-nolisten", "tcp"],
            pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(write)
        with os.fdopen(read) as f:
            display = f.readline().strip()
        if not display:
            raise SystemExit("Xvfb did not start")
        try:
            self._start(display)
        except BaseException:
            self.xvfb.terminate()
            raise

    def _start(self, display):
        from selenium.webdriver.firefox.service import Service
        env = dict(os.environ, DISPLAY=f":{display}")
        env.pop("WAYLAND_DISPLAY", None)
        options = webdriver.FirefoxOptions()
        options.binary_location = shutil.which("firefox-esr") or shutil.which("firefox")
        options.add_argument(f"--width={WIDTH}")
        options.add_argument(f"--height={HEIGHT}")
        options.enable_bidi = True
        self.driver = webdriver.Firefox(
            options=options,
            service=Service(shutil.which("geckodriver") or "geckodriver", env=env))
        self.driver.set_window_rect(0, 0, WIDTH, HEIGHT)
        self.errors = []
        self.driver.script.add_console_message_handler(
            lambda m: self.errors.append(f"console.{m.level}: {m.text}")
            if m.level == "error" else None)
        self.driver.script.add_javascript_error_handler(
            lambda e: self.errors.append(f"uncaught: {e.text}"))

    def console_errors(self):
        # BiDi events arrive on their own thread: give the last ones a moment.
        time.sleep(0.2)
        out, self.errors[:] = list(self.errors), []
        return out

    def quit(self):
        try:
            self.driver.quit()
        finally:
            self.xvfb.terminate()
            self.xvfb.wait(10)


started = time.monotonic()
if browser == "chromium":
    session = Chromium()
elif browser == "firefox":
    session = Firefox()
else:
    raise SystemExit(f"unknown browser {browser!r}: chromium or firefox")
driver = session.driver
driver.set_page_load_timeout(60)
out = {"browser": browser, "console_errors": [], "steps": [],
       "browser_version": driver.capabilities.get("browserVersion"),
       "browser_start_s": time.monotonic() - started}
# Network errors the test provokes on purpose (the invalid hand upload answers 422); Chromium
# logs them as errors.
expected = []


def logs(step):
    for message in session.console_errors():
        if any(e in message for e in expected):
            continue
        out["console_errors"].append({"step": step, "message": message})
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
                         f"at {driver.current_url}: {err.split()}; console: {session.console_errors()}")


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


def row_ids(css):
    return [int(tr.get_attribute("data-id")) for tr in driver.find_elements(By.CSS_SELECTOR, css)]


def texts(css):
    return [td.text for td in driver.find_elements(By.CSS_SELECTOR, css)]


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
    objects = texts("#skill-rows td.object")
    out["filtered_rows"] = len(objects)
    out["filtered_all_box"] = bool(objects) and all(o.startswith("box") for o in objects)
    ids = row_ids("#skill-rows tr")
    out["filtered_sorted_desc"] = ids == sorted(ids, reverse=True)
    out["hash_after_filter"] = driver.execute_script("return location.hash")
    unready()
    driver.find_element(By.ID, "next").click()
    wait_ready("skills")
    ids2 = row_ids("#skill-rows tr")
    out["next_page_continues"] = bool(ids2) and max(ids2) < min(ids)
    shot("skills-filtered")
    logs("filter")

    # 3. A skill: phases, the force plot drawn, contacts in 3D, nearest skills.
    go(f"{base}/#/skills/{skill_id}")
    wait_ready("skill")
    out["timeline_phases"] = len(driver.find_elements(By.CSS_SELECTOR, "#timeline div"))
    # The phase durations read in the grasp's order (the timeline's), not the API's alphabetical.
    timeline = list(dict.fromkeys(driver.execute_script(
        "return [...document.querySelectorAll('#timeline div')].map(d => d.textContent)")))
    facts = driver.execute_script("""
        const dt = [...document.querySelectorAll('dl.facts dt')].find(d => d.textContent === 'phases');
        return dt ? dt.nextElementSibling.textContent : '';""")
    out["phase_facts"] = facts
    out["phase_facts_in_time_order"] = bool(timeline) and [
        p.strip().split(" ")[0] for p in facts.split(",")] == timeline
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
    # The session list: newest first (the <script> session is among the newest), pages, filters.
    go(f"{base}/#/sessions")
    wait_ready("sessions")
    out["xss_alert"] = alert_open()
    out["xss_script_elements"] = driver.execute_script(
        "return [...document.querySelectorAll('main script')].length")
    out["foxglove_links"] = len(driver.find_elements(By.PARTIAL_LINK_TEXT, "open in Foxglove"))
    ids = row_ids("#session-rows tr")
    scenarios = texts("#session-rows td.scenario")
    out["sessions_rows"] = len(ids)
    out["sessions_newest_first"] = bool(ids) and ids == sorted(ids, reverse=True)
    out["sessions_first_scenario"] = scenarios[0] if scenarios else None
    out["xss_text_on_sessions"] = XSS in scenarios
    shot("sessions")
    unready()
    driver.find_element(By.ID, "sessions-next").click()
    wait_ready("sessions")
    ids2 = row_ids("#session-rows tr")
    out["sessions_next_continues"] = bool(ids2) and max(ids2) < min(ids)
    unready()
    driver.find_element(By.ID, "sessions-prev").click()
    wait_ready("sessions")
    out["sessions_prev_returns"] = row_ids("#session-rows tr") == ids
    form = driver.find_element(By.ID, "session-filters")
    form.find_element(By.NAME, "scenario").send_keys("sphere-lift")
    unready()
    driver.find_element(By.ID, "sessions-apply").click()
    wait_ready("sessions")
    scenarios = texts("#session-rows td.scenario")
    out["sessions_by_scenario"] = scenarios
    out["sessions_hash_after_filter"] = driver.execute_script("return location.hash")
    driver.find_element(By.NAME, "scenario").clear()
    Select(driver.find_element(By.CSS_SELECTOR, "#session-filters select[name=shape]")).select_by_value("box")
    unready()
    driver.find_element(By.ID, "sessions-apply").click()
    wait_ready("sessions")
    objects = texts("#session-rows td.object")
    ids = row_ids("#session-rows tr")
    out["sessions_by_shape_rows"] = len(objects)
    out["sessions_by_shape_all_box"] = bool(objects) and all(o == "box" for o in objects)
    out["sessions_by_shape_newest_first"] = ids == sorted(ids, reverse=True)
    shot("sessions-filtered")
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
    out["total_s"] = time.monotonic() - started
    session.quit()

print(json.dumps(out))
