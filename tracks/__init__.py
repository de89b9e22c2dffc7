"""Processed circuit data of SOfAR (installed as the package ``sofar_env.track_data``).

Each sub-folder holds one circuit built by ``python -m sofar_env.tracks build``;
see README.md in this folder for the format and provenance.
"""
