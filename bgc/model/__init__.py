"""Stage **load**: model text (YAML) -> Model: the document, the schema checks, expressions,
signals and the one place that names sympy symbols."""
