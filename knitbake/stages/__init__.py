"""The bake stages (each ends in a ``bake_*_stage`` function that ``knitbake.bake`` calls): dual scattering, correction
and shadowing, textures and flyaways, the I_M table."""
