"""Scenes defined outside piezodyn's tree (tests/test_third_scene.py): PIEZODYN_SCENES=scenes.<module> with
tests/ on the Python path registers them."""
