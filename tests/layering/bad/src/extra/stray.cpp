// Fixture: a folder that is no declared module.
