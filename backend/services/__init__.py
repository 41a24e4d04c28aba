"""Services: the acquisition loop, the live hub, image rendering."""
