"""Heat-transfer physics of the probe: solids and layer stack, heater power, forward models, the flux-driven model, type-K tables, the material library."""
