// Line plots of contact forces (uPlot, vendored).
import uPlot from './vendor/uplot/uPlot.esm.js';

const COLOURS = ['#d62728', '#1f77b4', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf'];

/**
 * Draws one plot into `el`: x values `xs` (s), one series per entry of `series`
 * ({label, values}), `yLabel` the axis; `marks` are [time_s, label] phase boundaries.
 */
export function linePlot(el, title, xs, series, yLabel, marks = []) {
  const width = Math.max(320, el.clientWidth || 600);
  const opts = {
    title,
    width,
    height: 220,
    scales: { x: { time: false } },
    axes: [{ label: 'time (s)' }, { label: yLabel }],
    series: [{ label: 't (s)' }, ...series.map((s, i) => ({
      label: s.label, stroke: COLOURS[i % COLOURS.length], width: 1.5,
    }))],
    hooks: {
      draw: [u => {
        const ctx = u.ctx;
        ctx.save();
        ctx.strokeStyle = '#9aa';
        ctx.fillStyle = '#567';
        ctx.font = `${10 * devicePixelRatio}px sans-serif`;
        for (const [t, label] of marks) {
          const x = u.valToPos(t, 'x', true);
          if (x < u.bbox.left || x > u.bbox.left + u.bbox.width) continue;
          ctx.beginPath();
          ctx.moveTo(x, u.bbox.top);
          ctx.lineTo(x, u.bbox.top + u.bbox.height);
          ctx.stroke();
          ctx.fillText(label, x + 2, u.bbox.top + 10 * devicePixelRatio);
        }
        ctx.restore();
      }],
    },
  };
  return new uPlot(opts, [xs, ...series.map(s => s.values)], el);
}
