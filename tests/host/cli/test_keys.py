"""``thermotouch keys new|list`` and signed ``flash --key [--force]`` on a simulated probe."""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import pytest

from edge.security.keys import PUBLIC_KIND, SECRET_KIND, key_id, read_key
from edge.security import ed25519
from host.keys import KEYS_ENV, default_keys_dir
from tests.support.cli import run, one_line_error


def test_keys_new_writes_a_secret_0600_and_a_public_file(capsys, tmp_path):
    code, out, err = run(capsys, "keys", "new", "--out", str(tmp_path / "k"), "--name", "lab")
    assert code == 0, err
    sec, pub = tmp_path / "k" / "lab.secret.json", tmp_path / "k" / "lab.public.json"
    assert stat.S_IMODE(os.stat(sec).st_mode) == 0o600
    s, p = json.loads(sec.read_text()), json.loads(pub.read_text())
    assert s["kind"] == SECRET_KIND and p["kind"] == PUBLIC_KIND and "secret_hex" not in p
    assert s["key_id"] == p["key_id"] == key_id(bytes.fromhex(p["public_hex"])) and s["key_id"] in out
    assert ed25519.public_key(bytes.fromhex(s["secret_hex"])) == bytes.fromhex(p["public_hex"])
    assert [f.name for f in (tmp_path / "k").iterdir() if f.name.startswith(".")] == []  # no temporaries left


def test_keys_new_never_overwrites_without_the_flag(capsys, tmp_path):
    d = tmp_path / "k"
    assert run(capsys, "keys", "new", "--out", str(d))[0] == 0
    before = (d / "thermotouch.secret.json").read_bytes()
    code, out, err = run(capsys, "keys", "new", "--out", str(d))
    assert code == 2 and "exists (use --overwrite" in one_line_error(err)
    assert (d / "thermotouch.secret.json").read_bytes() == before
    assert run(capsys, "keys", "new", "--out", str(d), "--overwrite")[0] == 0
    assert (d / "thermotouch.secret.json").read_bytes() != before


def test_keys_default_dir_is_the_environment_override(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv(KEYS_ENV, str(tmp_path / "env-keys"))
    assert default_keys_dir() == tmp_path / "env-keys"
    assert run(capsys, "keys", "new", "--name", "ci")[0] == 0
    code, out, err = run(capsys, "keys", "list")
    assert code == 0, err
    kid = read_key(tmp_path / "env-keys" / "ci.public.json").key_id
    assert f"ci.public.json" in out and "public" in out and "secret" in out and out.count(kid) == 2
    monkeypatch.delenv(KEYS_ENV)
    assert default_keys_dir() == Path.home() / ".config" / "thermotouch" / "keys"


def test_keys_list_reports_a_broken_file_and_a_missing_dir(capsys, tmp_path):
    (tmp_path / "junk.json").write_text('{"kind": "nope"}')
    code, out, err = run(capsys, "keys", "list", str(tmp_path))
    assert code == 0 and "junk.json" in out and "unreadable" in out
    code, out, err = run(capsys, "keys", "list", str(tmp_path / "none"))
    assert code == 2 and "does not exist" in one_line_error(err)


def test_keys_bad_name_is_one_line(capsys, tmp_path):
    code, out, err = run(capsys, "keys", "new", "--out", str(tmp_path), "--name", "../x")
    assert code == 2 and "argument --name" in one_line_error(err)


def _key(capsys, tmp_path):
    keys = tmp_path / "keys"
    assert run(capsys, "keys", "new", "--out", str(keys), "--name", "rel")[0] == 0
    return keys, str(keys / "rel.secret.json"), read_key(keys / "rel.public.json").key_id


def _trust(keys, work):
    """What an operator does on the probe: copy the public key file into its trusted_keys_dir."""
    (work / "trusted_keys").mkdir(parents=True)
    shutil.copy(keys / "rel.public.json", work / "trusted_keys")


@pytest.mark.hil
def test_flash_with_key_refused_until_the_probe_trusts_it(capsys, tmp_path):
    from thermotouch_models import DEFAULT_BUNDLE

    keys, secret, kid = _key(capsys, tmp_path)
    work = tmp_path / "probe"
    sim = ("--sim", "glass_15V", "--workdir", str(work))
    # The simulated probe trusts the key files in WORKDIR/trusted_keys: none yet.
    code, out, err = run(capsys, "flash", str(DEFAULT_BUNDLE), *sim, "--key", secret)
    assert code == 2
    assert f"refused the bundle: install refused, active model unchanged: signature by untrusted key {kid}" \
        in one_line_error(err)
    _trust(keys, work)
    code, out, err = run(capsys, "flash", str(DEFAULT_BUNDLE), *sim, "--key", secret)
    assert code == 0, err
    assert f"signed by key {kid}" in out


@pytest.mark.hil
def test_flash_of_an_older_signed_release_needs_force(capsys, tmp_path):
    from thermotouch_models import DEFAULT_BUNDLE

    keys, secret, kid = _key(capsys, tmp_path)
    work = tmp_path / "probe"
    _trust(keys, work)
    sim = ("--sim", "glass_15V", "--workdir", str(work))
    # An older release than the probe's model (same arrays, earlier created_utc).
    old = tmp_path / "old"
    shutil.copytree(DEFAULT_BUNDLE, old)
    m = json.loads((old / "manifest.json").read_text())
    m["created_utc"], m["model_version"] = "2020-01-01T00:00:00Z", "old-release"
    (old / "manifest.json").write_text(json.dumps(m, indent=2, sort_keys=True) + "\n")
    code, out, err = run(capsys, "flash", str(old), *sim, "--key", secret)
    assert code == 2
    line = one_line_error(err)
    assert "downgrade refused: update 'old-release' created 2020-01-01T00:00:00Z is not newer" in line
    assert "--force --key" in line
    code, out, err = run(capsys, "flash", str(old), *sim, "--force")
    assert code == 2 and "--force needs --key" in one_line_error(err)
    code, out, err = run(capsys, "flash", str(old), *sim, "--key", secret, "--force")
    assert code == 0, err
    assert "device runs old-release" in out and f"signed by key {kid}" in out


def test_flash_with_a_public_key_file_is_refused_before_the_device(capsys, tmp_path):
    from thermotouch_models import DEFAULT_BUNDLE

    assert run(capsys, "keys", "new", "--out", str(tmp_path))[0] == 0
    code, out, err = run(capsys, "flash", str(DEFAULT_BUNDLE), "--port", "/dev/thermotouch-not-needed",
                         "--key", str(tmp_path / "thermotouch.public.json"))
    assert code == 2
    assert "signing key refused" in one_line_error(err) and "secret key file" in err


@pytest.mark.hil
def test_objects_add_with_key_refused_until_the_probe_trusts_it(capsys, tmp_path):
    keys, secret, kid = _key(capsys, tmp_path)
    work = tmp_path / "probe"
    sim = ("--sim", "glass_15V", "--workdir", str(work))
    csv = tmp_path / "kitchen.csv"
    csv.write_text("name,class,e_W_s05_m2K\nmug,ceramic,1400\nsponge,foam,60\n")
    code, out, err = run(capsys, "objects", "add", str(csv), *sim, "--key", secret)
    assert code == 2 and f"signature by untrusted key {kid}" in one_line_error(err)
    _trust(keys, work)
    code, out, err = run(capsys, "objects", "add", str(csv), *sim, "--key", secret)
    assert code == 0, err
    code, out, err = run(capsys, "objects", "list", *sim)
    assert code == 0 and f"signed by {kid}" in out


def test_objects_add_with_a_public_key_file_is_refused_before_the_device(capsys, tmp_path):
    assert run(capsys, "keys", "new", "--out", str(tmp_path))[0] == 0
    csv = tmp_path / "kitchen.csv"
    csv.write_text("name,class,e_W_s05_m2K\nmug,ceramic,1400\n")
    code, out, err = run(capsys, "objects", "add", str(csv), "--port", "/dev/thermotouch-not-needed",
                         "--key", str(tmp_path / "thermotouch.public.json"))
    assert code == 2 and "signing key refused" in one_line_error(err)
