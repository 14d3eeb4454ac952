// The stand-alone page: connect to this server's websocket with the page's token.
import viewer, { socketModel } from "./app.js";

const token = new URLSearchParams(window.location.search).get("token") || "";
const scheme = window.location.protocol === "https:" ? "wss" : "ws";
const url = `${scheme}://${window.location.host}/ws?token=${encodeURIComponent(token)}`;
viewer.render({ model: socketModel(url), el: document.getElementById("app") });
