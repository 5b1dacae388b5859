"""ISSUE #35 §10: nothing from outside reaches the user's terminal as a control sequence."""

from host.cli.main import main
from host.cli.terminal import neutralise

ESC_NAME = "win\x1b]0;pwned\x07dow\x9b2J"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_neutralise_keeps_text_and_layout_and_escapes_controls():
    assert neutralise("e 1477 ± 12\tW\r\n") == "e 1477 ± 12\tW\r\n"
    assert neutralise(ESC_NAME) == "win\\x1b]0;pwned\\x07dow\\x9b2J"


def test_an_object_name_with_escapes_is_printed_visibly(capsys, tmp_path, glass_record):
    objs = tmp_path / "objects.csv"
    objs.write_text(f"name,class,k_W_mK,rho_kg_m3,c_J_kgK\n{ESC_NAME},glass,1.0,2500,800\n"
                    "lid,polymer,0.19,1180,1430\n")
    code, out, err = run(capsys, "estimate", "--csv", glass_record, "--objects", objs)
    text = out + err
    assert "\x1b" not in text and "\x07" not in text and "\x9b" not in text
    assert "win\\x1b]0;pwned\\x07dow" in text  # named, visibly: nothing silently dropped


def test_an_error_line_with_escapes_is_printed_visibly(capsys, tmp_path):
    code, out, err = run(capsys, "estimate", "--csv", tmp_path / "rec\x1b[2J.csv")
    assert code == 2 and "\x1b" not in err and "rec\\x1b[2J.csv" in err
