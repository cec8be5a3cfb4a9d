"""Commissioning recipes: YAML lists of sherpa steps, operator confirmations and expectations.

Above ``ops`` and below ``cli``: the runner does not know how a step is executed; the CLI
hands it a function that runs one ``sherpa`` command line and returns its exit code and output.
May import config, output_files and errors; never cli.
"""

from sherpa_cli.recipes.model import Expect, Recipe, Step, load_recipe

__all__ = ["Expect", "Recipe", "Step", "load_recipe"]
