// A small line chart of one series on a canvas (the training loss per step).

export class LineChart {
  constructor(canvas, label) {
    this.canvas = canvas;
    this.label = label;
    this.points = [];
  }

  clear() {
    this.points = [];
    this.draw();
  }

  add(x, y) {
    if (!Number.isFinite(x) || !Number.isFinite(y)) return;
    const last = this.points[this.points.length - 1];
    if (last && last[0] === x) last[1] = y;
    else this.points.push([x, y]);
    this.draw();
  }

  draw() {
    const canvas = this.canvas;
    const scale = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(canvas.clientWidth * scale));
    const height = Math.max(1, Math.round(canvas.clientHeight * scale));
    if (canvas.width !== width || canvas.height !== height) {
      canvas.width = width;
      canvas.height = height;
    }
    const context = canvas.getContext("2d");
    const style = getComputedStyle(canvas);
    context.clearRect(0, 0, width, height);
    context.font = `${11 * scale}px system-ui, sans-serif`;
    context.fillStyle = style.color;
    if (this.points.length < 2) {
      context.fillText(`${this.label}: waiting for training steps`, 8 * scale, 16 * scale);
      return;
    }
    const xs = this.points.map(([x]) => x);
    const ys = this.points.map(([, y]) => y);
    const [x0, x1] = [Math.min(...xs), Math.max(...xs)];
    const [y0, y1] = [Math.min(...ys), Math.max(...ys)];
    const pad = 24 * scale;
    const toX = (x) => pad + ((x - x0) / Math.max(1e-9, x1 - x0)) * (width - 2 * pad);
    const toY = (y) => height - pad - ((y - y0) / Math.max(1e-9, y1 - y0)) * (height - 2 * pad);
    context.strokeStyle = getComputedStyle(document.documentElement).getPropertyValue("--accent");
    context.lineWidth = 2 * scale;
    context.beginPath();
    this.points.forEach(([x, y], index) => {
      if (index === 0) context.moveTo(toX(x), toY(y));
      else context.lineTo(toX(x), toY(y));
    });
    context.stroke();
    context.fillText(`${this.label} ${y1.toPrecision(3)}`, 4 * scale, 12 * scale);
    context.fillText(y0.toPrecision(3), 4 * scale, height - 6 * scale);
    context.fillText(`step ${x1}`, width - 70 * scale, height - 6 * scale);
  }
}
