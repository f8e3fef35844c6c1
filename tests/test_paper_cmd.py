"""``vdps paper`` (vdps_hil.cli.paper_cmd): errors as one line."""

from __future__ import annotations


def test_cli_rejects_an_unknown_profile_in_one_line(capsys):
    from vdps_hil.cli.main import main

    assert main(["paper", "--quick", "--profile", "no-such-profile"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no-such-profile" in err[0]
