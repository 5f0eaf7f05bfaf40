"""Recipes: named inspection configurations of a cell, one active at a time."""

from backend.recipes.model import Recipe, RecipeOptions, options_for
from backend.recipes.service import (
    RecipeFields,
    activate,
    activate_number,
    active_recipe,
    create_recipe,
    delete_recipe,
    follower,
    get_recipe,
    list_recipes,
    resolve_options,
    update_recipe,
)

__all__ = ["Recipe", "RecipeFields", "RecipeOptions", "activate", "activate_number",
           "active_recipe", "create_recipe", "delete_recipe", "follower", "get_recipe",
           "list_recipes", "options_for", "resolve_options", "update_recipe"]  # fmt: skip
