"""Stage **load**: model text (YAML) -> Model. ``document``: text -> located YAML values;
``values``: the checks of one value; ``sections``: a reader per group of sections;
``load``: the entry point that runs them. Besides: ``model`` (the Model's dataclasses),
``expr`` (safe expressions), ``signals``, ``symbols`` (the one place that names sympy
symbols) and ``limits``."""
