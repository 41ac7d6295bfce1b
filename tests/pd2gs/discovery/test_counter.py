"""Part counters: rigid-motion RANSAC on synthetic motions; the VLM client against a local stub server."""
import base64
import io
import json
import threading
from http.server import BaseHTTPRequestHandler, HTTPServer

import numpy as np
import pytest
from PIL import Image

from pd2gs.discovery.counter import (PROMPT, CountError, count_rigid_motions, mode_count, parse_count,
                                     vlm_count)
from pd2gs.discovery.motion import dynamic_mask
from rsart.kinematics import joint_motion
from synthetic import articulated_means


def _thresh(md):
    return 0.05 * float(np.linalg.norm(md[-1] - md[0], axis=1).max())


def test_motion_counter_finds_two_parts():
    m, lab = articulated_means(outliers=20)
    md = m[:, dynamic_mask(m, 0.15)]
    mc = count_rigid_motions(md, _thresh(md))
    assert mc.n == 2
    assert sum(mc.support) > 0.9 * md.shape[1]


def test_motion_counter_three_parts_and_one_part():
    m, lab = articulated_means()
    rng = np.random.default_rng(5)
    lid = rng.uniform([-0.3, -0.2, 0.5], [0.3, 0.2, 0.51], size=(300, 3))
    T = [joint_motion("revolute", np.array([0.0, 1.0, 0.0]), np.array([-0.3, 0.0, 0.5]), -v) for v in (0, .3, .6, .9)]
    lid_m = np.stack([lid @ t[:3, :3].T + t[:3, 3] for t in T])
    m3 = np.concatenate([m, lid_m], axis=1)
    md = m3[:, dynamic_mask(m3, 0.15)]
    assert count_rigid_motions(md, _thresh(md)).n == 3
    only_drawer = m[:, lab == 2]
    assert count_rigid_motions(only_drawer, _thresh(only_drawer)).n == 1


@pytest.mark.parametrize("text,n", [
    ("Number of moved components: [2]", 2),
    ("number of moved components: 3", 3),
    ("Sure! Number of moved components: [ 1 ] because the door opened.", 1),
    ("Two components moved.", None),
    ("", None),
])
def test_parse_count(text, n):
    assert parse_count(text) == n


def test_mode_count_ties_and_failures():
    assert mode_count([2, 2, 3, None]) == 2
    assert mode_count([3, 2]) == 2                      # tie -> smaller
    with pytest.raises(CountError):
        mode_count([None, None])


class _Stub(BaseHTTPRequestHandler):
    answers: list = []
    requests: list = []

    def do_POST(self):
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        type(self).requests.append({"body": body, "auth": self.headers.get("Authorization")})
        ans = type(self).answers[len(type(self).requests) - 1]
        if ans == "HTTP500":
            self.send_response(500); self.end_headers(); return
        data = json.dumps({"choices": [{"message": {"role": "assistant", "content": ans}}]}).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *a):
        pass


@pytest.fixture
def stub():
    srv = HTTPServer(("127.0.0.1", 0), _Stub)
    th = threading.Thread(target=srv.serve_forever, daemon=True)
    th.start()
    _Stub.requests = []
    yield srv, f"http://127.0.0.1:{srv.server_address[1]}/v1/chat/completions"
    srv.shutdown()
    srv.server_close()


def _img(c):
    a = np.zeros((8, 10, 3), dtype=np.uint8)
    a[..., 0] = c
    return a


def test_vlm_client_prompt_payload_and_mode(stub, monkeypatch):
    _, url = stub
    _Stub.answers = ["Number of moved components: [2]", "garbage", "HTTP500", "Number of moved components: [2]",
                     "Number of moved components: [3]"]
    monkeypatch.setenv("TEST_VLM_KEY", "sk-test")
    pairs = [(_img(10 * i), _img(10 * i + 5)) for i in range(5)]
    n, answers = vlm_count(pairs, url, "test-model", "TEST_VLM_KEY", timeout_s=5)
    assert n == 2
    assert len(answers) == 5 and answers[2].startswith("<error")
    req = _Stub.requests[0]
    assert req["auth"] == "Bearer sk-test"
    body = req["body"]
    assert body["model"] == "test-model"
    content = body["messages"][0]["content"]
    assert content[0] == {"type": "text", "text": PROMPT}
    assert "How many components moved?" in PROMPT and "Number of moved components: [N]" in PROMPT
    urls = [c["image_url"]["url"] for c in content[1:]]
    assert len(urls) == 2 and all(u.startswith("data:image/png;base64,") for u in urls)
    img = np.asarray(Image.open(io.BytesIO(base64.b64decode(urls[1].split(",", 1)[1]))))
    assert np.array_equal(img, pairs[0][1])            # the second image of the first pair, lossless


def test_vlm_all_malformed_raises(stub):
    _, url = stub
    _Stub.answers = ["I think two", "HTTP500"]
    with pytest.raises(CountError, match="no parsable VLM answer"):
        vlm_count([(_img(0), _img(1))] * 2, url, "m", "", timeout_s=5)


def test_vlm_unreachable_is_a_count_error():
    with pytest.raises(CountError):
        vlm_count([(_img(0), _img(1))], "http://127.0.0.1:9/none", "m", "", timeout_s=2)
    with pytest.raises(CountError, match="must start with http"):
        from pd2gs.discovery.counter import ask_vlm
        ask_vlm("file:///etc/passwd", _img(0), _img(1), "m")
