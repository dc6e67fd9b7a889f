"""The search's budget counts its thread's CPU seconds by default (search.budget_clock "cpu": a loaded machine, where
the search waits for a core, plans what a quiet one plans), the wall clock for the replanner, whose simulated world
does not wait for the planner."""

import time

import pytest

from trajectotree.config import ConfigError, SearchConfig
from trajectotree.search.tree import SearchClock


def test_a_cpu_budget_does_not_count_time_spent_waiting_and_a_wall_budget_does():
    cpu, wall = SearchConfig(time_budget_s=0.05), SearchConfig(time_budget_s=0.05, budget_clock="wall")
    clocks = SearchClock.start(cpu), SearchClock.start(wall)
    time.sleep(0.1)  # as a search that another process keeps off the core
    assert not clocks[0].over(cpu) and clocks[1].over(wall)
    assert clocks[0].elapsed() >= 0.1 and clocks[1].elapsed() >= 0.1  # the reported time is the wall clock's


def test_an_unknown_clock_is_refused_by_name():
    with pytest.raises(ConfigError, match="search.budget_clock = 'gpu' is unknown; valid: cpu, wall"):
        SearchConfig(budget_clock="gpu")
