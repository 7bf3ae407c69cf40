"""Stages **expand** and **causality**: Model -> BondGraph (bodies and joints as multibonds)
-> CausalGraph (SCAP)."""
