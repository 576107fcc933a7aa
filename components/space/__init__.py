"""The space environment as plain models, no I/O: the Sun and the Moon, and what the orbit and
dynamics components take from them. Any component domain may use this layer; it uses none of them."""
