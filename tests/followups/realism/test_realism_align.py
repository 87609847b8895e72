"""The realism kit's alignment aids: edge images of renders, and ``align.html``, the render laid over
the phone's live camera view (the 3DB paper's Section 5 app, as one web page).

The browser tests drive the system's headless Chromium (``tests/conftest.py``'s ``chromium``);
the live-camera ones launch a second one, from the same Playwright, with Chromium's fake camera
playing a tiny ``.y4m`` file written here (two flat colours, left and right), so what the page
shows and saves can be checked pixel by pixel. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import base64
import io
import re
from html import unescape
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from sweep3d.followups.realism.align import PAGE, AlignShot, write_align_page
from sweep3d.followups.realism.edges import EDGE_RGB, edge_image
from tests.helpers import REPO
from tests.helpers.realism import fake_camera, open_align, write_y4m

ARTIFACTS = REPO / "test-artifacts"
CAMERA_SIZE = (320, 240)  # the fake camera's frame, width × height (4:3, as a phone's)
CAMERA_LEFT, CAMERA_RIGHT = (0, 128, 128), (230, 120, 20)  # its two halves
FILL = (0, 0, 255)  # the middle of every render
EVIL_JOB = 'job"<img src=x onerror=alert(1)></script>&amp;'
EVIL_CAPTION = "<b>bold</b> & </title><script>alert(2)</script>"
#: The kit's shots: (job id, width, height, caption); a square render, a wide one and a tall one.
SHOTS = [("quick-0", 64, 64, "mug · yaw 30°"), ("quick-1", 96, 48, "mug · yaw 60°"),
         (EVIL_JOB, 48, 64, EVIL_CAPTION)]
TOLERANCE = 14  # per channel: YUV 4:2:0 round trips, JPEG and bilinear scaling
EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//|url\(\s*["']?\s*(?:https?:)?//|@import""", re.I)


def render_like(width: int, height: int) -> np.ndarray:
    """A stand-in render: dark grey, with a FILL rectangle over its middle half."""
    rgb = np.full((height, width, 3), 40, dtype=np.uint8)
    rgb[height // 4:3 * height // 4, width // 4:3 * width // 4] = FILL
    return rgb


def fit(box_w: float, box_h: float, w: float, h: float) -> tuple[float, float, float, float]:
    """The centred rectangle of aspect w:h fitted inside a box: (left, top, width, height)."""
    s = min(box_w / w, box_h / h)
    return (box_w - w * s) / 2, (box_h - h * s) / 2, w * s, h * s


def close(pixel: Any, expected: Any, tolerance: float = TOLERANCE) -> bool:
    return bool(np.all(np.abs(np.asarray(pixel, float)[:3] - np.asarray(expected, float)) <= tolerance))


# ---------------------------------------------------------------- edge images


def square(side: int = 32, lo: int = 8, hi: int = 24, inside: int = 200, outside: int = 30) -> np.ndarray:
    rgb = np.full((side, side, 3), outside, dtype=np.uint8)
    rgb[lo:hi, lo:hi] = inside
    return rgb


def test_edge_image_outlines_a_square_and_leaves_the_rest_transparent() -> None:
    rgba = edge_image(square())
    assert rgba.shape == (32, 32, 4) and rgba.dtype == np.uint8
    opaque = rgba[..., 3] == 255
    assert set(np.unique(rgba[..., 3])) == {0, 255}
    assert (rgba[opaque][:, :3] == EDGE_RGB).all() and (rgba[~opaque] == 0).all()
    rows, cols = np.nonzero(opaque)
    # every edge pixel within a pixel of the square's border (rows and columns 8 and 23)
    near = np.minimum(np.abs(rows[:, None] - [7.5, 23.5]).min(1), np.abs(cols[:, None] - [7.5, 23.5]).min(1))
    inside = (rows >= 7) & (rows <= 24) & (cols >= 7) & (cols <= 24)
    assert (near <= 1).all() and inside.all()
    # all four sides drawn along (nearly) their whole length
    for side in (opaque[7:10, 8:24].any(0), opaque[22:25, 8:24].any(0), opaque[8:24, 7:10].any(1),
                 opaque[8:24, 22:25].any(1)):
        assert side.mean() >= 0.9, side
    assert not opaque[11:21, 11:21].any() and not opaque[:5].any() and not opaque[:, 28:].any()


def test_an_edge_between_two_colours_of_one_brightness_is_drawn() -> None:
    rgb = np.zeros((24, 24, 3), dtype=np.uint8)
    rgb[:, :12] = (255, 0, 0)
    rgb[:, 12:] = (0, 130, 0)  # the same luma (0.299 · 255 ≈ 0.587 · 130): a grey edge detector sees nothing
    opaque = edge_image(rgb)[..., 3] > 0
    assert opaque[2:-2, 11:13].any(1).all()  # the boundary, top to bottom
    assert not opaque[:, :9].any() and not opaque[:, 15:].any()


def test_flat_faint_and_noisy_images_have_no_edges() -> None:
    rng = np.random.default_rng(0)
    flat = np.full((40, 40, 3), 120, dtype=np.uint8)
    faint = square(40, 10, 30, inside=128, outside=120)  # 8 levels of contrast: texture, not an outline
    noisy = (flat.astype(int) + rng.integers(-2, 3, flat.shape)).astype(np.uint8)
    for rgb in (flat, faint, noisy):
        assert not edge_image(rgb)[..., 3].any()


def test_edge_image_is_deterministic_and_thicker_on_large_renders() -> None:
    small = square()
    assert edge_image(small).tobytes() == edge_image(small.copy()).tobytes()
    big = square(672, 168, 504)  # 3 × 224: smoothed and drawn 3 px wide, to look as the small one does
    opaque = edge_image(big)[..., 3] > 0
    widths = opaque[200:480, 150:190].sum(1)  # across the left side, row by row
    assert (widths >= 3).all() and (widths <= 6).all(), widths


@pytest.mark.parametrize("bad", [np.zeros((8, 8), np.uint8), np.zeros((8, 8, 4), np.uint8),
                                 np.zeros((8, 8, 3), np.float32), np.zeros((0, 8, 3), np.uint8)])
def test_edge_image_refuses_what_is_not_an_rgb_render(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="edge_image needs"):
        edge_image(bad)


# ---------------------------------------------------------------- the page, as written


def write_kit(folder: Path, shots: list[tuple[str, int, int, str]] = SHOTS) -> tuple[Path, list[AlignShot]]:
    """A kit folder as ``realism pick`` writes one: renders and edge images, then ``align.html``."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for i, (job, width, height, caption) in enumerate(shots):
        rgb = render_like(width, height)
        Image.fromarray(rgb).save(folder / f"render-{i}.png")
        Image.fromarray(edge_image(rgb), "RGBA").save(folder / f"edges-{i}.png")
        written.append(AlignShot(job, f"render-{i}.png", f"edges-{i}.png", caption))
    return write_align_page(folder, written), written


def data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


@pytest.fixture(scope="module")
def kit(tmp_path_factory) -> Path:
    page, _ = write_kit(tmp_path_factory.mktemp("kit"))
    return page


def test_the_page_is_one_file_that_requests_nothing_and_prints_data_as_text(kit: Path) -> None:
    assert kit.name == PAGE
    html = kit.read_text(encoding="utf-8")
    assert not EXTERNAL.search(html)
    csp = unescape(re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', html).group(1))
    assert csp.startswith("default-src 'none'; script-src 'sha256-") and "connect-src" not in csp  # no request
    for i in range(len(SHOTS)):
        assert data_uri(kit.parent / f"render-{i}.png") in html and data_uri(kit.parent / f"edges-{i}.png") in html
    # the job id and caption travel only inside the JSON block, with < > & escaped
    assert EVIL_JOB not in html and "<img src=x" not in html and "alert(2)" in html
    assert html.count("<script") == 2 and html.count("</script>") == 2


def test_the_page_refuses_shots_it_cannot_show(tmp_path: Path) -> None:
    _, shots = write_kit(tmp_path, SHOTS[:2])
    with pytest.raises(ValueError, match="at least one shot"):
        write_align_page(tmp_path, [])
    with pytest.raises(ValueError, match="quick-0"):
        write_align_page(tmp_path, [shots[0], AlignShot("quick-0", "render-1.png", "edges-1.png", "")])
    with pytest.raises(ValueError, match="edges-1.png"):  # a 96 × 48 edge image for a 64 × 64 render
        write_align_page(tmp_path, [AlignShot("a", "render-0.png", "edges-1.png", "")])
    with pytest.raises(FileNotFoundError):
        write_align_page(tmp_path, [AlignShot("a", "gone.png", "edges-0.png", "")])


# ---------------------------------------------------------------- the page, in a browser


@pytest.fixture(scope="module")
def camera_browser(chromium, tmp_path_factory):
    """A second headless Chromium whose camera is a fake device playing CAMERA_LEFT | CAMERA_RIGHT,
    and that grants the camera without asking."""
    w, h = CAMERA_SIZE
    frame = np.zeros((h, w, 3), dtype=np.uint8)
    frame[:, :w // 2], frame[:, w // 2:] = CAMERA_LEFT, CAMERA_RIGHT
    with fake_camera(chromium, write_y4m(tmp_path_factory.mktemp("camera") / "camera.y4m", frame)) as browser:
        yield browser


def assert_clean(page_path: Path, events: dict[str, list]) -> None:
    """No script error, console error or dialog; no request but the page (and its own blob: URLs)."""
    assert events["errors"] == [] and events["console"] == [] and events["dialogs"] == []
    assert {url for url in events["requests"] if not url.startswith("blob:")} == {page_path.as_uri()}


def box(page: Any, selector: str) -> tuple[float, float, float, float]:
    return tuple(page.evaluate(f"() => {{ const b = document.querySelector({selector!r}).getBoundingClientRect();"
                               " return [b.left, b.top, b.width, b.height]; }"))


def expected_overlay(page: Any, frame_selector: str, frame_size: tuple[int, int],
                     render_size: tuple[int, int]) -> tuple[float, float, float, float]:
    """Where the overlay belongs: the render's aspect fitted inside the frame as the element
    displays it (object-fit: contain)."""
    left, top, width, height = box(page, frame_selector)
    fx, fy, fw, fh = fit(width, height, *frame_size)
    ox, oy, ow, oh = fit(fw, fh, *render_size)
    return left + fx + ox, top + fy + oy, ow, oh


def assert_boxes_match(got: tuple[float, ...], expected: tuple[float, ...]) -> None:
    assert all(abs(g - e) <= 1.0 for g, e in zip(got, expected)), (got, expected)


def settled_overlay(page: Any, frame_selector: str, frame_size: tuple[int, int],
                    render_size: tuple[int, int]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The overlay's box and where it belongs, measured once the page's layout holds still (the
    notice above the frame may still be hiding when the photo's load is signalled: two reads of
    one moment, not of two)."""
    before = None
    for _ in range(40):
        now = (box(page, "#overlay"), expected_overlay(page, frame_selector, frame_size, render_size))
        if now == before:
            break
        before = now
        page.wait_for_timeout(50)
    return now


def screen(page: Any) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)


def text(page: Any, selector: str) -> str:
    return page.evaluate(f"() => document.querySelector({selector!r}).textContent")


@pytest.mark.browser
def test_the_live_camera_shows_the_render_over_its_frames_and_captures_them_by_job(kit: Path, camera_browser) -> None:
    with open_align(camera_browser, kit) as (page, events):
        assert page.evaluate("() => document.documentElement.dataset.mode") == "live"
        page.wait_for_function("() => { const v = document.getElementById('video');"
                               " return !v.paused && v.readyState >= 2 && v.currentTime > 0.2; }", timeout=15_000)
        assert page.evaluate("() => { const v = document.getElementById('video'); return [v.videoWidth, v.videoHeight]; }") \
            == list(CAMERA_SIZE)
        assert page.is_visible("#capture") and page.is_hidden("#take")
        assert (text(page, "#job"), text(page, "#caption"), text(page, "#counter")) == ("quick-0", SHOTS[0][3], "1 / 3")

        # the overlay: over the video's displayed frame, at the render's aspect, at the slider's opacity
        page.fill("#opacity", "70")
        assert page.evaluate("() => getComputedStyle(document.getElementById('overlay')).opacity") == "0.7"
        left, top, width, height = box(page, "#overlay")
        assert_boxes_match((left, top, width, height), expected_overlay(page, "#video", CAMERA_SIZE, (64, 64)))
        assert page.evaluate("() => document.getElementById('overlay').src") == data_uri(kit.parent / "render-0.png")
        pixels = screen(page)
        camera = pixels[round(top + height / 2), max(2, round(left / 2))]  # the frame beside the overlay
        assert close(camera, CAMERA_LEFT)
        drawn = pixels[round(top + height / 2), round(left + 0.375 * width)]  # the render's FILL over the left half
        assert close(drawn, 0.7 * np.array(FILL) + 0.3 * camera), (drawn, camera)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "align-live.png"))

        # previous / next: the shot, its caption and its overlay's aspect change
        assert page.is_disabled("#prev")
        page.click("#next")
        assert (text(page, "#job"), text(page, "#counter")) == ("quick-1", "2 / 3")
        assert page.evaluate("() => document.getElementById('overlay').src") == data_uri(kit.parent / "render-1.png")
        assert_boxes_match(box(page, "#overlay"), expected_overlay(page, "#video", CAMERA_SIZE, (96, 48)))
        page.click("#toggle")
        assert page.evaluate("() => document.getElementById('overlay').src") == data_uri(kit.parent / "edges-1.png")
        page.screenshot(path=str(ARTIFACTS / "align-live-edges.png"))

        # capture: the camera frame at its full size, without the overlay, named by the job
        with page.expect_download() as download:
            page.click("#capture")
        assert download.value.suggested_filename == "quick-1.jpg"
        with Image.open(download.value.path()) as photo:
            assert photo.format == "JPEG" and photo.size == CAMERA_SIZE
            saved = np.asarray(photo.convert("RGB")).astype(int)
        w, h = CAMERA_SIZE
        # every pixel the camera's (but the few where JPEG blurs its halves' boundary): no overlay
        assert np.abs(saved[:, :w // 2 - 8] - CAMERA_LEFT).max() <= TOLERANCE
        assert np.abs(saved[:, w // 2 + 8:] - CAMERA_RIGHT).max() <= TOLERANCE
        assert text(page, "#counter") == "2 / 3 \u2713" and "quick-1.jpg" in text(page, "#status")

        page.click("#prev")
        assert text(page, "#job") == "quick-0" and page.evaluate(
            "() => document.getElementById('overlay').src") == data_uri(kit.parent / "edges-0.png")  # edges kept

        # a phone turned to landscape: the bar moves aside, the overlay follows the video's new box
        page.set_viewport_size({"width": 700, "height": 360})
        page.wait_for_timeout(100)
        assert_boxes_match(box(page, "#overlay"), expected_overlay(page, "#video", CAMERA_SIZE, (64, 64)))
        assert box(page, "#bar")[0] > box(page, "#stage")[0]
        page.screenshot(path=str(ARTIFACTS / "align-live-landscape.png"))
        assert_clean(kit, events)


def photo_file(folder: Path, name: str, size: tuple[int, int], colour: tuple[int, int, int]) -> Path:
    path = folder / name
    Image.new("RGB", size, colour).save(path, quality=90) if name.endswith(".jpg") else Image.new(
        "RGB", size, colour).save(path)
    return path


@pytest.mark.browser
def test_without_a_camera_the_phones_camera_app_takes_the_photo_shown_under_the_overlay(
        kit: Path, chromium, tmp_path: Path) -> None:
    jpeg = photo_file(tmp_path, "IMG_0001.jpg", (300, 200), (20, 190, 40))
    png = photo_file(tmp_path, "screen.png", (90, 160), (200, 20, 40))
    with open_align(chromium, kit) as (page, events):  # this Chromium has no camera
        assert page.evaluate("() => document.documentElement.dataset.mode") == "photo"
        assert page.is_visible("#take") and page.is_hidden("#capture") and page.is_disabled("#save")
        assert page.get_attribute("#file", "capture") == "environment"
        assert "No live camera" in text(page, "#notice") and page.is_visible("#notice")

        page.set_input_files("#file", str(jpeg))
        page.wait_for_function("() => document.documentElement.dataset.photo === '1'")
        assert page.is_visible("#photo") and page.is_enabled("#save")
        (left, top, width, height), expected = settled_overlay(page, "#photo", (300, 200), (64, 64))
        assert_boxes_match((left, top, width, height), expected)
        drawn = screen(page)[round(top + height / 2), round(left + width / 2)]
        assert close(drawn, 0.5 * np.array(FILL) + 0.5 * np.array([20, 190, 40])), drawn  # the photo under the render
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "align-photo.png"))
        with page.expect_download() as download:
            page.click("#save")
        assert download.value.suggested_filename == "quick-0.jpg"
        assert Path(download.value.path()).read_bytes() == jpeg.read_bytes()  # a JPEG as taken, EXIF and all

        page.set_input_files("#file", str(png))  # a retake, in another format: encoded as JPEG
        page.wait_for_function("() => document.getElementById('photo').naturalWidth === 90")
        with page.expect_download() as download:
            page.click("#save")
        assert download.value.suggested_filename == "quick-0.jpg"
        with Image.open(download.value.path()) as saved:
            assert saved.format == "JPEG" and saved.size == (90, 160)
            assert close(saved.convert("RGB").getpixel((45, 80)), (200, 20, 40))

        page.click("#next")  # the photo was the first shot's: not offered for the next
        assert page.is_hidden("#photo") and page.is_disabled("#save") and text(page, "#job") == "quick-1"
        assert_clean(kit, events)


@pytest.mark.browser
@pytest.mark.parametrize(("init", "reason"), [
    ("Object.defineProperty(window, 'isSecureContext', {value: false});", "secure page"),
    ("navigator.mediaDevices.getUserMedia = () => Promise.reject(new DOMException('no', 'NotAllowedError'));",
     "permission was denied"),
], ids=["insecure", "denied"])
def test_an_insecure_page_or_a_denied_camera_falls_back_to_the_file_input(
        kit: Path, camera_browser, init: str, reason: str) -> None:
    spy = ("window.__asked = 0; const ask = navigator.mediaDevices.getUserMedia.bind(navigator.mediaDevices);"
           " navigator.mediaDevices.getUserMedia = (c) => { window.__asked += 1; return ask(c); };")
    with open_align(camera_browser, kit, init_script=spy + init) as (page, events):
        assert page.evaluate("() => document.documentElement.dataset.mode") == "photo"
        assert reason in text(page, "#notice") and page.is_visible("#take") and page.is_hidden("#capture")
        assert page.is_hidden("#video")
        if reason == "secure page":
            assert page.evaluate("() => window.__asked") == 0  # not even asked
        assert_clean(kit, events)


@pytest.mark.browser
def test_a_job_id_with_markup_is_shown_as_text(kit: Path, chromium) -> None:
    with open_align(chromium, kit) as (page, events):
        page.keyboard.press("ArrowRight")
        page.keyboard.press("ArrowRight")
        assert text(page, "#job") == EVIL_JOB and text(page, "#caption") == EVIL_CAPTION
        assert page.evaluate("() => document.querySelectorAll('img').length") == 2  # the photo's and the overlay's
        assert page.evaluate("() => document.querySelectorAll('#info *').length") == 3  # counter, job, caption
        assert page.title() == "Align 3 shots · sweep3d"
        assert_clean(kit, events)
