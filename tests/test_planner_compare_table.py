"""frog-twin --planner-compare's table: cells, sums and the floor column (issue 19.2)."""

from frog_twin.planner_compare import compare_table


def _run(path, planner, mean_cm, floor_cm, finished=True, sim=0, fallbacks=0):
    return {"path": path, "planner": planner, "seed": 1, "mean_distance_m": mean_cm / 100,
            "finished": finished, "simulator_decisions": sim, "fallbacks": fallbacks, "floor_m": floor_cm / 100}


def test_floor_is_the_lowest_of_the_planners_models_and_sums_add_up():
    # the paper's model turns tighter (lower floor) than the project's on the sine
    results = [_run("sine", "project", 0.8, 0.62), _run("sine", "paper", 1.0, 0.35),
               _run("line", "paper", 0.5, 0.0), _run("line", "project", 0.3, 0.0, finished=False)]
    table = compare_table(results)
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]] for line in table.splitlines()
            if line.startswith("| ") and not line.startswith("| path")}
    assert rows["sine"][0] == "0.35"
    assert rows["sine"][1:3] == ["1.00 (1/1)", "0.80 (1/1)"]
    assert rows["line"][2] == "0.30 (0/1)"
    assert rows["**sum**"][1:3] == ["**1.50**", "**1.10**"]
