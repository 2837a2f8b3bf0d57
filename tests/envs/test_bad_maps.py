"""Bad map files and map texts, as a user meets them: each refusal names the map, the line and what
is allowed."""
import pytest

from bad_input import QUICK, cli_error


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
