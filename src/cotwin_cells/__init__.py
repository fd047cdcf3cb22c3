"""Cells and worlds outside cotwin's generic core, registered as scene kinds (entry-point group
`cotwin.scenes`, cotwin.pmodel.scenes): core never imports them by name."""
