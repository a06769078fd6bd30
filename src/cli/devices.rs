//! `rollcam devices`: list GenICam cameras and USB cameras / LED controllers.

use anyhow::Result;

#[derive(clap::Args, Debug, Clone)]
pub struct DevicesArgs {
    /// Also enable aravis' Fake interface (rollcam's fake camera XML) before listing.
    #[arg(long)]
    pub fake: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: DevicesArgs) -> Result<()> {
    let mut report = serde_json::Map::new();
    report.insert("genicam".into(), genicam(&args)?);
    report.insert("usb".into(), usb(&args));
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}

#[cfg(feature = "aravis")]
fn genicam(args: &DevicesArgs) -> Result<serde_json::Value> {
    if args.fake {
        rollcam_hw::camera::aravis::enable_fake_interface()?;
    }
    let cams = rollcam_hw::camera::aravis::discover();
    if !args.json {
        println!("GenICam cameras (aravis): {}", cams.len());
        for c in &cams {
            println!(
                "  {:<32} {} {}  {}  [{}]",
                c.spec(),
                c.vendor.as_deref().unwrap_or("?"),
                c.model.as_deref().unwrap_or("?"),
                c.address.as_deref().unwrap_or(""),
                c.protocol.as_deref().unwrap_or("")
            );
        }
        if cams.is_empty() {
            println!("  none found (use --fake to list aravis' fake camera as aravis:Fake_1)");
        }
    }
    Ok(serde_json::to_value(cams)?)
}

#[cfg(not(feature = "aravis"))]
fn genicam(args: &DevicesArgs) -> Result<serde_json::Value> {
    let msg = "GenICam cameras: feature `aravis` is off in this build (cargo build --release --features aravis)";
    if !args.json {
        println!("{msg}");
    }
    Ok(serde_json::Value::String(msg.into()))
}

#[cfg(feature = "usb")]
fn usb(args: &DevicesArgs) -> serde_json::Value {
    match rollcam_hw::usb::discover() {
        Ok(devs) => {
            if !args.json {
                println!("USB cameras and LED controllers: {}", devs.len());
                for d in &devs {
                    println!(
                        "  {:04x}:{:04x} {:<28} {:?}{} at bus {} port {}",
                        d.vendor_id,
                        d.product_id,
                        d.vendor_name.as_deref().unwrap_or("?"),
                        d.kind,
                        if d.usb3_vision { " (USB3 Vision)" } else { "" },
                        d.bus,
                        d.location()
                    );
                }
            }
            serde_json::to_value(devs).unwrap_or(serde_json::Value::Null)
        }
        Err(e) => {
            if !args.json {
                println!("USB: {e}");
            }
            serde_json::Value::String(e.to_string())
        }
    }
}

#[cfg(not(feature = "usb"))]
fn usb(args: &DevicesArgs) -> serde_json::Value {
    let msg = "USB devices: feature `usb` is off in this build (cargo build --release --features usb)";
    if !args.json {
        println!("{msg}");
    }
    serde_json::Value::String(msg.into())
}
