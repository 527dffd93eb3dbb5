"""The environment layer: engine, scenarios, PettingZoo env and rendering."""
