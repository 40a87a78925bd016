"""One run of a scene: settings checked, the mode machine called, the Result built
(``simulate``). Imports the layers below (jit, integration, hybrid, model, results)."""
