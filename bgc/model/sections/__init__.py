"""Stage **load**, its second half: the readers of a model document's sections, one
module per group, each from located YAML values to parts of the Model.

``context``: what the readers share (the names declared, the parameters' values, the
bodies and joints read so far); ``parameters``: parameters and signals; ``settings``:
the simulation settings; ``bodies``: gravity, bodies, frames, axes and points;
``joints``: joints, their springs and actuators; ``excitation``: the excitation section;
``network``: elements, bonds and outputs. ``bgc.model.load.from_document`` calls them in
order.
"""
