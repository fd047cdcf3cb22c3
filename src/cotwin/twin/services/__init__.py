"""What runs beside a twin: deviation checking, the history store, what-if forks, the publisher, the
OPC UA plant and the page. Imports cotwin.twin.project and .assembly (and the layers below the twin)."""
