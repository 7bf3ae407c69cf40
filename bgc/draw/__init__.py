"""``bgc draw``: a model's bond graph as a picture, in standard notation, with the causal
strokes SCAP assigned. Three steps, each one structure in and one out:
``diagram.of_model`` (model file -> ``Diagram``: what is drawn, grouped by body and joint,
marked), ``layout.layout`` (``Diagram`` -> ``Layout``: where, by igraph's Sugiyama layout)
and ``render.render`` (``Layout`` -> SVG, PNG or PDF file, by matplotlib)."""
