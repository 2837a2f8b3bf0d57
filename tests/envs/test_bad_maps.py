"""Bad map files and map texts, as a user meets them: each refusal names the map, the line and what
is allowed."""
import re

import pytest

from bad_input import NOT_A_FILE, QUICK, cli_error, not_a_file
from oapo_lite.envs.maps import MAPS, MapError, parse_maze


def test_a_map_header_after_its_grid_is_named():
    from oapo_lite.envs.maps import MapError, parse_maze

    with pytest.raises(MapError, match=r"has its 'agents' line after the grid; the header lines .* come first"):
        parse_maze("start: 1,1\n###\n#*#\n###\nagents: red")


def test_a_map_file_error_names_the_file(tmp_path, capsys):
    path = tmp_path / "my_maze.txt"
    path.write_text("agents: red black\nstart: 1,1 1,1\n#####\n#..*##\n#####\n")
    assert f"map '{path}' has ragged rows" in cli_error(capsys, "train", *QUICK, "--env", str(path),
                                                         "--out", str(tmp_path))
    path.write_bytes(b"\xff\xfe\x00garbage")
    assert f"cannot read the map file {path}" in cli_error(capsys, "train", *QUICK, "--env", str(path),
                                                            "--out", str(tmp_path))


@pytest.mark.parametrize("route, max_steps, words", [
    (100, 50, ["max_steps = 50", "longest shortest route is 100 moves", "max_steps >= 100"]),
    (150, 200, ["best team return is -0.5", "routes shorter than 100 moves"]),
])
def test_a_maze_beyond_the_time_limit_or_without_a_positive_optimum_is_refused(tmp_path, capsys, route, max_steps,
                                                                                words):
    row = "#R" + "." * (route - 1) + "*#"
    path = tmp_path / "corridor.txt"
    path.write_text(f"agents: red\nstart: 1,1\n{'#' * len(row)}\n{row}\n{'#' * len(row)}\n")
    err = cli_error(capsys, "train", *QUICK, "--out", str(tmp_path / "out"), "--env", str(path),
                     "--max-steps", str(max_steps))
    assert all(w in err for w in words) and not (tmp_path / "out").exists()  # refused before a run folder


# ---------------------------------------------------------------- issue 53: a header given twice

BLACK_RED_GRID = "\n".join(MAPS["black_red"].splitlines()[2:])


@pytest.mark.parametrize("header, words", [
    ("agents: red black\nagents: blue\nstart: 7,4", "gives its 'agents' line 2 times (lines [1, 2])"),
    ("agents: red black\nstart: 7,4 7,4\nstart: 7,1 7,7", "gives its 'start' line 2 times (lines [2, 3])"),
    # neighbours: the same value again, a key spelled with spaces, three times, a blank line between
    ("agents: red black\nagents: red black\nstart: 7,4 7,4", "gives its 'agents' line 2 times (lines [1, 2])"),
    ("agents: red black\n agents : blue\nstart: 7,4 7,4", "gives its 'agents' line 2 times (lines [1, 2])"),
    ("start: 7,4 7,4\nagents: red black\n\nstart: 7,4 7,4\nstart: 7,4 7,4", "gives its 'start' line 3 times (lines [1, 4, 5])"),
])
def test_a_header_line_given_twice_is_refused_with_its_line_numbers(header, words):
    """Before issue 53 the last line won: a map saying red and black, then blue, trained one blue agent."""
    with pytest.raises(MapError, match=re.escape(f"map 'm' {words}; give each header line once")):
        parse_maze(f"{header}\n{BLACK_RED_GRID}", name="m")
    parse_maze(f"agents: red black\nstart: 7,4 7,4\n{BLACK_RED_GRID}", name="m")  # once each: the map itself


def test_a_map_file_with_a_header_given_twice_trains_nothing(tmp_path, capsys):
    path = tmp_path / "twice.txt"
    path.write_text(f"agents: red black\nagents: blue\nstart: 7,4\n{BLACK_RED_GRID}\n")
    err = cli_error(capsys, "train", *QUICK, "--env", str(path), "--out", str(tmp_path / "out"))
    assert f"map '{path}' gives its 'agents' line 2 times (lines [1, 2])" in err and not (tmp_path / "out").exists()


# ---------------------------------------------------------------- issue 53: a map path that is no file


@pytest.mark.parametrize("kind", ["FIFO", "socket", "device", "link to a device"])
def test_a_map_path_that_is_no_regular_file_is_named_and_never_opened(tmp_path, capsys, kind):
    """A FIFO would block the read for ever and /dev/zero never end; each is named by its kind."""
    with not_a_file(tmp_path / "map.txt", kind) as path:
        err = cli_error(capsys, "train", *QUICK, "--env", str(path), "--out", str(tmp_path / "out"))
    assert f"--env {path} is {NOT_A_FILE[kind]}, not a file; allowed: a built-in map" in err
