"""Safe zip extraction: zip-slip, symlinks, zip bombs, limits, junk are refused; nothing is left behind."""
from __future__ import annotations

import io
import stat
import zipfile

import pytest

from leaderboards.archive import ArchiveError, ArchiveLimits, extract_zip, find_submission_file


def _zip(entries: list[tuple], path) -> None:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for e in entries:
            if isinstance(e[0], zipfile.ZipInfo):
                zf.writestr(e[0], e[1])
            else:
                zf.writestr(e[0], e[1])


def _left_behind(dirpath) -> list[str]:
    return [p.name for p in dirpath.iterdir() if p.name != "a.zip"]


def test_good_archive(tmp_path):
    _zip([("sub/submission.json", b"{}"), ("sub/o/m0/static.ply", b"ply\n")], tmp_path / "a.zip")
    out = extract_zip(tmp_path / "a.zip", tmp_path / "x")
    assert (out / "sub" / "o" / "m0" / "static.ply").read_bytes() == b"ply\n"
    assert find_submission_file(out) == out / "sub" / "submission.json"


@pytest.mark.parametrize("name,msg", [("../evil.txt", "zip-slip"), ("a/../../evil.txt", "zip-slip"),
                                      ("/etc/evil", "absolute"), ("C:/evil", "absolute"),
                                      ("a\\..\\evil", "invalid characters")])
def test_zip_slip_refused(tmp_path, name, msg):
    _zip([("submission.json", b"{}"), (name, b"x")], tmp_path / "a.zip")
    with pytest.raises(ArchiveError, match=msg):
        extract_zip(tmp_path / "a.zip", tmp_path / "x")
    assert _left_behind(tmp_path) == []
    assert not (tmp_path.parent / "evil.txt").exists()


def test_symlink_refused(tmp_path):
    info = zipfile.ZipInfo("link")
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    _zip([("submission.json", b"{}"), (info, b"/etc/passwd")], tmp_path / "a.zip")
    with pytest.raises(ArchiveError, match="symlink"):
        extract_zip(tmp_path / "a.zip", tmp_path / "x")
    assert _left_behind(tmp_path) == []


def test_zip_bomb_refused_by_ratio_and_by_total(tmp_path):
    _zip([("submission.json", b"{}"), ("big.ply", b"\0" * (20 * 1024 ** 2))], tmp_path / "a.zip")
    assert (tmp_path / "a.zip").stat().st_size < 100_000
    with pytest.raises(ArchiveError, match="ratio"):
        extract_zip(tmp_path / "a.zip", tmp_path / "x")
    with pytest.raises(ArchiveError, match="unpacks to"):
        extract_zip(tmp_path / "a.zip", tmp_path / "y", ArchiveLimits(max_unpacked_bytes=1024 ** 2, max_ratio=1e9))
    assert _left_behind(tmp_path) == []


def test_lying_header_is_caught_while_inflating(tmp_path):
    """A header that declares a small size cannot sneak a large payload past the total limit."""
    _zip([("data.bin", bytes(range(256)) * 8192)], tmp_path / "a.zip")  # 2 MiB, poorly compressible
    raw = bytearray((tmp_path / "a.zip").read_bytes())
    # patch the central directory's uncompressed size (offset 24 in the CD entry) to 10 bytes
    cd = raw.rfind(b"PK\x01\x02")
    raw[cd + 24:cd + 28] = (10).to_bytes(4, "little")
    (tmp_path / "a.zip").write_bytes(bytes(raw))
    with pytest.raises(ArchiveError):
        extract_zip(tmp_path / "a.zip", tmp_path / "x", ArchiveLimits(max_unpacked_bytes=1024 ** 2, max_ratio=1e9))
    assert _left_behind(tmp_path) == []


def test_limits_and_junk(tmp_path):
    (tmp_path / "a.zip").write_bytes(b"this is not a zip")
    with pytest.raises(ArchiveError, match="not a zip"):
        extract_zip(tmp_path / "a.zip", tmp_path / "x")
    _zip([(f"f{i}", b"") for i in range(30)], tmp_path / "a.zip")
    with pytest.raises(ArchiveError, match="entries"):
        extract_zip(tmp_path / "a.zip", tmp_path / "x", ArchiveLimits(max_entries=10))
    with pytest.raises(ArchiveError, match="limit is 100"):
        extract_zip(tmp_path / "a.zip", tmp_path / "x", ArchiveLimits(max_upload_bytes=100))
    _zip([("a/x.json", b"{}"), ("b/y.json", b"{}")], tmp_path / "a.zip")
    with pytest.raises(ArchiveError, match="no submission.json"):
        find_submission_file(extract_zip(tmp_path / "a.zip", tmp_path / "z"))
